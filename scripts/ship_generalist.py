"""Ship a generalist with warpcut: copy the policy a finished ``warpcut generalist`` run kept, and its
``generalist.json`` with the command that trained it and the figures it reached, into
``agents/data/generalist/`` (what ``generalist`` plays: docs/results.md, "One policy for every contour").

Run: python scripts/ship_generalist.py RUN [--member RUN2 ...] [--zero-shot RESULTS.json ...] [--into DIR];
without RUN, the generalist in DIR (the shipped one) stays and each --member joins it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> None:
    from agents.generalist import SHIPPED_DIR
    from agents.pipelines.generalist import ship_generalist

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, nargs="?", help="default: keep the policy of the one in --into")
    parser.add_argument(
        "--into", type=Path, default=SHIPPED_DIR, help="its folder (default: the one warpcut ships)"
    )
    parser.add_argument(
        "--member",
        action="append",
        default=[],
        type=Path,
        help="another finished run, trained with the same env settings (e.g. --seed 1): shipped as a member "
        "the generalist chooses per contour on validation episodes (repeat for more)",
    )
    parser.add_argument(
        "--zero-shot",
        nargs="*",
        default=[],
        type=Path,
        help="evaluate runs' results.json with the generalist column: their means go into the figures",
    )
    args = parser.parse_args()
    zero_shot = {}
    for path in args.zero_shot:
        report = json.loads(path.read_text())
        contours = [row["contour"] for row in report["rows"]]
        config = json.loads((path.parent / "config.json").read_text())
        zero_shot[",".join(config["contours"])] = {
            "contours": len(contours),
            "trials": report["trials"],
            **{k: round(v, 1) for k, v in report["mean"].items()},
        }
    print(f"wrote {ship_generalist(args.run, args.into, zero_shot, args.member)}")


if __name__ == "__main__":
    main()
