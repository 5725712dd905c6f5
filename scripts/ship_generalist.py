"""Ship a generalist with warpcut: copy the policy a finished ``warpcut generalist`` run kept, and its
``generalist.json`` with the command that trained it and the figures it reached, into
``agents/data/generalist/`` (what ``generalist`` plays: docs/results.md, "One policy for every contour").

Run: python scripts/ship_generalist.py RUN [--zero-shot RESULTS.json ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> None:
    from agents.generalist import SHIPPED_DIR
    from agents.pipelines.generalist import ship_generalist

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
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
    print(f"wrote {ship_generalist(args.run, SHIPPED_DIR, zero_shot)}")


if __name__ == "__main__":
    main()
