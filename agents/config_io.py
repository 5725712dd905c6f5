"""Settings as files: a config dataclass (nested dataclasses of plain fields) read from a TOML, YAML or JSON
file or a named preset, changed by ``key=value`` overrides, checked field by field, and written back out.

The dataclasses themselves (:mod:`agents.jobs`, :class:`~agents.config.TrainConfig`,
:class:`~warpcut.sim.config.SimConfig`, :class:`~envs.options.EnvConfig`) hold every default; this module only
moves values in and out of them, so a file, ``--set`` and a flag all reach the same field:

- :func:`read_file` reads ``.toml``, ``.yaml``/``.yml`` or ``.json`` (a run directory's ``config.json`` can be
  given back as is), or a preset's name (:data:`PRESETS`, files in ``agents/presets/``);
- :func:`parse_override` reads ``train.es.sigma=0.01`` (the value in YAML: ``true``, ``null``, ``[a, b]``);
- :func:`apply` sets dotted keys on a dataclass, each value checked against the field's type, with an error
  that names the key and where it came from;
- :func:`to_plain` / :func:`to_yaml` write one out (``--print-config``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from warpcut.io import MAX_NESTING, check_nesting
from warpcut.validation import ConfigError

MAX_VALUES = 100_000
"""How many values a config file or a ``--set`` value may expand to: YAML's aliases let a few hundred bytes
expand to billions (8 levels of 10), which checking or printing them would walk for hours; a config holds
a few hundred."""

MAX_INTEGER = 2**31 - 1
"""The largest integer any setting takes (the seeds' range, as ``--seed``'s): a larger one would overflow
where it reaches NumPy, torch, Warp or the clock (a progress line's ETA) after the work had started."""

PRESETS_DIR = Path(__file__).parent / "presets"
"""Where the named presets live: ``NAME.yaml``."""


def presets() -> list[str]:
    """The named presets (``--config NAME``)."""
    return sorted(p.stem for p in PRESETS_DIR.glob("*.yaml"))


class _KeyTwice(ValueError):
    """A mapping gives a key twice."""


def _unique_keys(pairs: list[tuple[Any, Any]]) -> dict:
    """A mapping of ``pairs`` (a JSON object's, a YAML mapping's), or :class:`_KeyTwice` naming a key given
    twice: a parser would keep the last without a word."""
    data: dict = {}
    for key, value in pairs:
        if key in data:
            raise _KeyTwice(f"{key}: given twice in one mapping; give it once")
        data[key] = value
    return data


def _yaml_load(text: str) -> Any:
    """YAML's safe load, refusing a key given twice in one mapping (:func:`_unique_keys`)."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict:
        merge = "tag:yaml.org,2002:merge"  # a key merged in (<<: *alias) may be given again: an override
        _unique_keys([(loader.construct_object(k), None) for k, _ in node.value if k.tag != merge])
        return loader.construct_mapping(node)

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return yaml.load(text, Loader=Loader)  # noqa: S506 -- a SafeLoader


def read_file(source: str | Path) -> dict:
    """The settings in a TOML, YAML or JSON file, or of a named preset, as a dict.

    Raises:
        ValueError: The file cannot be read or parsed, or does not hold a mapping; the message names the
            file and the fix.
    """
    path = Path(source)
    if not path.exists() and str(source) in presets():
        path = PRESETS_DIR / f"{source}.yaml"
    if not path.exists():
        names = ", ".join(presets())
        raise ValueError(f"--config: {source}: no such file, nor a preset ({names})")
    if not path.is_file():
        raise ValueError(f"--config: {path}: not a file; give a .toml, .yaml or .json file")
    suffix = path.suffix.lower()
    try:
        text = path.read_text()
        if suffix == ".toml":
            import tomllib

            data = tomllib.loads(text)
        elif suffix in (".yaml", ".yml", ".json"):
            data = _yaml_load(text) if suffix != ".json" else json.loads(text, object_pairs_hook=_unique_keys)
        else:
            raise ValueError(
                f"--config: {path}: unknown format {suffix or '(none)'}; give .toml, .yaml or .json"
            )
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--config: {path}: cannot be read ({exc})") from None
    except ValueError as exc:
        if str(exc).startswith("--config"):
            raise
        raise ValueError(f"--config: {path}: not valid {suffix[1:].upper()} ({_one_line(exc)})") from None
    except RecursionError:  # too deep for the parser itself
        raise ValueError(f"--config: {path}: nests deeper than {MAX_NESTING} levels") from None
    except Exception as exc:  # yaml's errors
        raise ValueError(f"--config: {path}: not valid YAML ({_one_line(exc)})") from None
    check_nesting(data, f"--config: {path}", items=MAX_VALUES)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"--config: {path}: holds a {type(data).__name__}; give a mapping of settings")
    return data


def parse_override(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` as ``(key, value)``, the value read as YAML (``3``, ``0.1``, ``true``, ``null``,
    ``[gravity, noise]``, ``{gravity: [0, 1042]}``, or else text)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ValueError(f"--set: expected KEY=VALUE, e.g. train.iterations=30 (got {text!r})")
    try:
        parsed = _yaml_load(value) if value.strip() else ""
    except RecursionError:
        raise ValueError(f"--set {key}: nests deeper than {MAX_NESTING} levels") from None
    except _KeyTwice as exc:
        raise ValueError(f"--set {key}: {exc}") from None
    except Exception:  # not YAML: text
        parsed = value
    return key, check_nesting(parsed, f"--set {key}", items=MAX_VALUES)


def flatten(data: Mapping, prefix: str = "") -> dict[str, Any]:
    """A nested mapping as ``{dotted key: value}`` (values that are mappings of a field are flattened too)."""
    flat: dict[str, Any] = {}
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value and not _is_free_mapping(name):
            flat.update(flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


FREE_MAPPINGS = ("randomize_ranges", "es_randomize_ranges")
"""Fields whose value is itself a mapping of free keys (``{parameter: [low, high]}``), not of fields."""


def _is_free_mapping(key: str) -> bool:
    return key.split(".")[-1] in FREE_MAPPINGS


def apply(config: Any, changes: Mapping[str, Any], where: str) -> Any:
    """A copy of the dataclass ``config`` with each dotted key of ``changes`` set (nested mappings are
    flattened first), each value checked against its field's type.

    Args:
        config: A dataclass instance (fields may be dataclasses themselves).
        changes: ``{"train.es.sigma": 0.01, ...}`` or nested ``{"train": {"es": {"sigma": 0.01}}}``.
        where: Where the changes come from, for errors (e.g. ``"--set"`` or a file's name).

    Raises:
        ValueError: An unknown key (with the known ones at its level) or a value of the wrong type, naming
            the key and ``where``.
    """
    for key, value in flatten(changes).items():
        config = _set(config, key.split("."), value, key, where)
    return config


def _set(config: Any, path: list[str], value: Any, key: str, where: str) -> Any:
    name, rest = path[0], path[1:]
    fields = {f.name: f for f in dataclasses.fields(config)}
    if name not in fields:
        known = ", ".join(sorted(fields))
        prefix = key[: len(key) - len(".".join(path))].rstrip(".")
        raise ValueError(f"{where}: {key}: unknown setting; {prefix or 'the top level'} has {known}")
    hint = typing.get_type_hints(type(config))[name]
    current = getattr(config, name)
    if rest:
        if dataclasses.is_dataclass(current):
            return dataclasses.replace(config, **{name: _set(current, rest, value, key, where)})
        if isinstance(current, dict) or current is None and _is_free_mapping(name):
            merged = dict(current or {})
            merged[".".join(rest)] = value
            try:
                return dataclasses.replace(config, **{name: _convert(merged, hint, key, where)})
            except ConfigError as error:
                raise error.renamed(f"{where}: {key}") from None
        raise ValueError(f"{where}: {key}: {'.'.join(path[:1])} is a single setting, not a section")
    if dataclasses.is_dataclass(current) and not isinstance(value, dict):
        raise ValueError(f"{where}: {key}: is a section; set its fields, e.g. {key}.FIELD=VALUE")
    if dataclasses.is_dataclass(current):
        return dataclasses.replace(config, **{name: apply(current, value, where)})
    converted = _convert(value, hint, key, where)
    try:  # a dataclass that checks its fields as it is made (warpcut.validation) names them as Class.field
        return dataclasses.replace(config, **{name: converted})
    except ConfigError as error:
        raise error.renamed(f"{where}: {key}") from None


def _convert(value: Any, hint: Any, key: str, where: str) -> Any:
    """``value`` as the type ``hint`` takes it (a list for a tuple field becomes a tuple), or
    ``ValueError``."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INTEGER:
        raise ValueError(
            f"{where}: {key}: {str(value)[:30]} is beyond any setting's range (integers up to {MAX_INTEGER})"
        )
    converted = _try(value, hint)
    if converted is _NO:
        raise ValueError(f"{where}: {key}: expected {_describe(hint)} (got {value!r:.60})")
    return converted


_NO = object()


def _try(value: Any, hint: Any) -> Any:
    """``value`` converted to ``hint``, or :data:`_NO` if it is not one."""
    origin = typing.get_origin(hint)
    if hint is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(hint):
            converted = _try(value, option)
            if converted is not _NO:
                return converted
        return _NO
    if hint is type(None):
        return None if value is None else _NO
    if hint is bool:
        return value if isinstance(value, bool) else _NO
    if hint is int:
        return value if isinstance(value, int) and not isinstance(value, bool) else _NO
    if hint is float:
        if isinstance(value, str):  # "inf" (to_plain's, as JSON has no infinity), or "1e-3" (YAML 1.1 text)
            try:
                value = float(value)
            except ValueError:
                return _NO
            return _NO if math.isnan(value) else value
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return float(value) if ok and not (isinstance(value, float) and math.isnan(value)) else _NO
    if hint is str:
        return value if isinstance(value, str) else _NO
    if hint is np.ndarray:
        return _NO  # given as a list, read by the Sequence option
    if origin in (list, tuple, Sequence, typing.Sequence) or hint in (list, tuple):
        if isinstance(value, str) and typing.get_args(hint) and typing.get_args(hint)[0] is str:
            value = [v.strip() for v in value.split(",") if v.strip()]  # "gravity,noise"
        if not isinstance(value, list | tuple):
            return _NO
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                return _NO
            items = [_try(v, a) for v, a in zip(value, args, strict=True)]
        else:
            item = args[0] if args else Any
            items = [_try(v, item) for v in value]
        if any(i is _NO for i in items):
            return _NO
        return tuple(items) if origin is tuple else list(items)
    if origin is dict or hint is dict:
        if not isinstance(value, Mapping):
            return _NO
        args = typing.get_args(hint)
        if not args:
            return dict(value)
        items = {k: _try(v, args[1]) for k, v in value.items()}
        return (
            _NO
            if any(v is _NO for v in items.values()) or not all(isinstance(k, str) for k in items)
            else items
        )
    if dataclasses.is_dataclass(hint):
        return _NO
    return value  # another type: the dataclass's own checks judge it


def _describe(hint: Any) -> str:
    """A type as words for an error."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        words = list(dict.fromkeys(_describe(a) for a in typing.get_args(hint)))
        if "a number" in words and "an integer" in words:  # an integer is a number
            words.remove("an integer")
        if "a list" in words and any(w.startswith("a list (") for w in words):  # the typed list says it
            words.remove("a list")
        return " or ".join(words)
    names = {bool: "true or false", int: "an integer", float: "a number", str: "text", type(None): "null"}
    if hint in names:
        return names[hint]
    if hint is np.ndarray:
        return "a list"
    if origin in (list, tuple, Sequence, typing.Sequence):
        args = typing.get_args(hint)
        return f"a list ({_describe(args[0])} each)" if args else "a list"
    if origin is dict:
        return "a mapping"
    return getattr(hint, "__name__", str(hint))


def to_plain(config: Any) -> Any:
    """A dataclass (or value) as plain JSON/YAML values: nested dicts, lists, numbers, text, null."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return {f.name: to_plain(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, Mapping):
        return {str(k): to_plain(v) for k, v in config.items()}
    if isinstance(config, list | tuple | np.ndarray):
        return [to_plain(v) for v in config]
    if isinstance(config, np.generic):
        config = config.item()
    if isinstance(config, float) and math.isinf(config):
        return "inf" if config > 0 else "-inf"
    if isinstance(config, Path):
        return str(config)
    return config


def to_yaml(config: Any) -> str:
    """A dataclass as YAML that :func:`read_file` reads back."""
    import yaml

    return yaml.safe_dump(to_plain(config), sort_keys=False, default_flow_style=False, width=110)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:200]
