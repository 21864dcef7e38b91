"""Dataset configuration: one schema, validated and defaulted alike by the CLI and the workflow.

``rules/schemas/config.schema.yaml`` (JSON Schema 2020-12) types every section and key of
``datasets/config.yaml``, holds every default and rejects unknown keys at every level. The
workflow (``rules/common.smk``) validates with :func:`validate_config` here, as the API and the
CLI do through :func:`load_config`: the same schema with the same default filling (a
``properties`` validator that first sets the defaults of absent keys, then descends, as
``snakemake.utils.validate(set_default=True)`` would), so both see identical dicts.

A bad key or value raises :class:`ConfigError` whose message is one line naming the file, the key
path, the value and what is allowed, e.g.::

    datasets/config.yaml: preprocess.rate_hx: unknown key (allowed: rate_hz, gap_multiple, ...)
    datasets/config.yaml: preprocess.rate_hz: 'fast' is not a number

Unknown keys are reported before any other error (a misspelt key usually explains its
sibling's "missing" value), then errors in document order, so the message is deterministic.

Stage code receives its section as a plain dict and turns it into a
``@dataclass(frozen=True, kw_only=True)`` with the one generic :func:`build`; the dataclass
defaults themselves are read from the schema (:func:`cfield`), so a default is written once.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import functools
import math
import os
import re
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable

import yaml

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = ROOT / "datasets" / "config.yaml"
SCHEMA_PATH = ROOT / "rules" / "schemas" / "config.schema.yaml"

_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _UniqueKeyLoader(_Loader):  # type: ignore[misc, valid-type]
    """The safe loader, refusing a key repeated in one mapping: YAML keeps the last one, so a
    second ``preprocess:`` block would silently drop the whole first one."""


def _unique_mapping(loader, node, deep=False):
    first: dict[Any, int] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            line = first.setdefault(key, key_node.start_mark.line + 1)
        except TypeError:  # an unhashable key: the schema names it
            continue
        if line != key_node.start_mark.line + 1:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first on line {line})", key_node.start_mark)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)


class ConfigError(ValueError):
    """A configuration file or value is invalid; the message names the file and key."""


# --- the schema ------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def _schema() -> dict[str, Any]:
    return yaml.load(SCHEMA_PATH.read_text(), Loader=_Loader)


def schema() -> dict[str, Any]:
    """The config schema (a deep copy of ``rules/schemas/config.schema.yaml``)."""
    return copy.deepcopy(_schema())


def _resolve(node: Mapping[str, Any], root: Mapping[str, Any]) -> Mapping[str, Any]:
    """Follow a local ``$ref`` (``#/$defs/...``); sibling keys of the ``$ref`` win."""
    while isinstance(node, Mapping) and "$ref" in node:
        ref = node["$ref"]
        if not ref.startswith("#/"):
            raise ConfigError(f"{SCHEMA_PATH}: only local $ref are supported, got {ref!r}")
        target: Any = root
        for part in ref[2:].split("/"):
            target = target[part]
        node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def _subschema(path: str) -> Mapping[str, Any]:
    """The schema of a dotted key path (``*`` steps into a map's ``additionalProperties``)."""
    root = _schema()
    node: Mapping[str, Any] = root
    for part in [p for p in path.split(".") if p]:
        node = _resolve(node, root)
        props = node.get("properties") or {}
        if part in props:
            node = props[part]
        elif isinstance(node.get("additionalProperties"), Mapping) and (
                part == "*" or part not in props):
            node = node["additionalProperties"]
        else:
            raise KeyError(f"config schema has no key {path!r} (at {part!r})")
    return _resolve(node, root)


# --- defaults ----------------------------------------------------------------------------------

def _fill(node: Mapping[str, Any], inst: Any, root: Mapping[str, Any]) -> None:
    """Set schema defaults into ``inst`` in place, as the validator below does (no jsonschema
    import: used at import time by :func:`cfield`)."""
    node = _resolve(node, root)
    if not isinstance(inst, dict):
        return
    for branch in [*node.get("oneOf", ()), *node.get("anyOf", ())]:
        b = _resolve(branch, root)
        if b.get("type") == "object" or "properties" in b:
            _fill(b, inst, root)
    props = node.get("properties") or {}
    for k, sub in props.items():
        if k not in inst and "default" in sub:
            inst[k] = copy.deepcopy(sub["default"])
        if k in inst:
            _fill(sub, inst[k], root)
    addl = node.get("additionalProperties")
    if isinstance(addl, Mapping):
        for k in inst:
            if k not in props:
                _fill(addl, inst[k], root)


@functools.lru_cache(maxsize=None)
def _default_at(path: str) -> Any:
    parts = [p for p in path.split(".") if p]
    root = _schema()
    inst: dict[str, Any] = {}
    cur = inst
    for part in parts[:-1]:   # placeholders for map entries ("*") so their defaults are filled
        cur = cur.setdefault(part, {})
    _fill(root, inst, root)
    cur = inst
    for part in parts:
        if not isinstance(cur, dict) or part not in cur:
            raise KeyError(f"config schema has no default for {path!r}")
        cur = cur[part]
    return cur


def default_at(path: str) -> Any:
    """The schema default of a dotted key path, nested defaults filled (``*``: a map entry)."""
    return copy.deepcopy(_default_at(path))


def defaults() -> dict[str, Any]:
    """The fully defaulted config of an empty file (what ``uavpipe config --defaults`` prints)."""
    return validate_config({})


#: ``$defs`` documented once as types (``<mount>.roll_deg``) rather than at every use
SHARED_TYPES = ("mount", "stick", "physical", "window", "ros_custom", "columnmap", "size_row", "hmm_override")


def _shared_ref(node: Any) -> str | None:
    """The shared type a schema node refers to (directly or as a oneOf branch), if any."""
    if not isinstance(node, Mapping):
        return None
    refs = [node.get("$ref")] + [b.get("$ref") for b in [*node.get("oneOf", ()), *node.get("anyOf", ())]
                                 if isinstance(b, Mapping)]
    for r in refs:
        if r and r.startswith("#/$defs/") and r[len("#/$defs/"):] in SHARED_TYPES:
            return r[len("#/$defs/"):]
    items = node.get("items")
    return _shared_ref(items) if isinstance(items, Mapping) else None


def key_paths(max_depth: int = 8) -> list[tuple[str, dict[str, Any]]]:
    """Every key of the schema as ``(dotted path, resolved schema)``, in schema order.

    Map entries appear as ``<name>`` (``preprocess.vehicles.<name>.imu_mount``); the keys of the
    :data:`SHARED_TYPES` appear once, as ``<type>.<key>`` (``<mount>.roll_deg``), and where
    they are used the path ends at the key that takes the type.
    """
    root = _schema()
    out: dict[str, dict[str, Any]] = {}

    def walk(node: Mapping[str, Any], prefix: str, depth: int) -> None:
        if depth > max_depth:
            return
        node = _resolve(node, root)
        branches = [node, *(_resolve(b, root) for b in [*node.get("oneOf", ()), *node.get("anyOf", ())])]
        for b in branches:
            for k, sub in (b.get("properties") or {}).items():
                path = f"{prefix}.{k}" if prefix else k
                out.setdefault(path, {**_resolve(sub, root), "x-shared": _shared_ref(sub)})
                if not _shared_ref(sub):
                    walk(sub, path, depth + 1)
            addl = b.get("additionalProperties")
            if isinstance(addl, Mapping) and prefix and not _shared_ref(addl):
                walk(addl, f"{prefix}.<name>", depth + 1)

    walk(root, "", 0)
    for t in SHARED_TYPES:
        if t != "hmm_override":   # the keys of the hmm section
            walk(root["$defs"][t], f"<{t}>", 1)
    return list(out.items())


def _type_word(s: Mapping[str, Any]) -> str:
    root = _schema()
    shared = s.get("x-shared") or _shared_ref(s)
    if shared == "hmm_override":
        return "mapping of hmm keys"
    if shared and s.get("type") != "array" and "oneOf" not in s:
        return f"<{shared}>"
    if "enum" in s:
        return " \\| ".join(str(v) for v in s["enum"])
    if "const" in s:
        return str(s["const"])
    if "oneOf" in s or "anyOf" in s:
        return " or ".join(f"<{_shared_ref(b)}>" if _shared_ref(b) else _type_word(_resolve(b, root))
                           for b in s.get("oneOf", s.get("anyOf", ())))
    t = s.get("type")
    ts = t if isinstance(t, list) else [t] if t else ["any"]
    words = []
    for x in ts:
        if x == "array":
            it = s.get("items")
            inner = (f"<{_shared_ref(it)}>" if _shared_ref(it) else _type_word(_resolve(it, root))) \
                if isinstance(it, Mapping) else "any"
            n = f"{s['minItems']} " if s.get("minItems") is not None and s.get("minItems") == s.get("maxItems") else ""
            words.append(f"list of {n}{inner}")
        elif x == "object" and isinstance(s.get("additionalProperties"), Mapping):
            ad = s["additionalProperties"]
            words.append(f"map of <{_shared_ref(ad)}>" if _shared_ref(ad) else f"map of {_type_word(_resolve(ad, root))}")
        else:
            words.append({"object": "mapping"}.get(x, x))
    return " or ".join(words)


def markdown_reference() -> str:
    """The key reference of ``datasets/README.md`` (generated: ``python -m pipeline.config``)."""
    import json

    lines = ["| key | type | default | meaning |", "|---|---|---|---|"]
    for path, s in key_paths():
        dflt = json.dumps(s["default"]) if "default" in s else ""
        if path.startswith("<") and "." not in path:
            continue
        desc = " ".join(str(s.get("description", "")).split()).replace("|", "\\|")
        typ = _type_word(s)
        lines.append(f"| `{path}` | {typ} | {('`' + dflt + '`') if dflt else ''} | {desc} |")
    return "\n".join(lines) + "\n"


# --- validation --------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def _validator_class():
    from jsonschema import Draft202012Validator, validators

    validate_properties = Draft202012Validator.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        # as snakemake.utils.validate(set_default=True), but a copy: never alias the schema
        if isinstance(instance, dict):
            for prop, sub in properties.items():
                if "default" in sub and prop not in instance:
                    instance[prop] = copy.deepcopy(sub["default"])
        yield from validate_properties(validator, properties, instance, schema)

    # a YAML .nan/.inf passes every minimum/maximum (comparisons with NaN are false) and would
    # fail deep inside a stage: "number" means a finite one
    checker = Draft202012Validator.TYPE_CHECKER.redefine(
        "number", lambda _c, x: isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x))
    return validators.extend(Draft202012Validator, {"properties": set_defaults}, type_checker=checker)


def _validate(instance: Any, schema_: Mapping[str, Any], where: str) -> None:
    errors = list(_validator_class()(schema_).iter_errors(instance))
    if errors:
        found = sorted((_explain(e, schema_) for e in errors), key=lambda r: r[:2])
        msg = found[0][2]
        # the line stays one line; the other keys in trouble are named, so a file with three
        # mistakes is not fixed in three runs
        key = msg.split(": ")[0]
        others = [k for k in dict.fromkeys(r[2].split(": ")[0] for r in found[1:]) if k != key]
        if others:
            msg += f" (also wrong: {', '.join(others[:5])}{' and more' if len(others) > 5 else ''})"
        raise ConfigError(f"{where}{msg}")


def _where(source: str | os.PathLike | None) -> str:
    if source is None:
        return ""
    p = Path(source)
    try:
        p = p.resolve().relative_to(Path.cwd().resolve())
    except ValueError:
        pass
    return f"{p}: "


def validate_config(cfg: Mapping[str, Any] | None, *, source: str | os.PathLike | None = None
                    ) -> dict[str, Any]:
    """Validate a whole config and return a deep copy with every default filled, in canonical
    form (:func:`typed`: numbers as the schema types them, declared keys in schema order).

    Raises
    ------
    ConfigError
        One line: ``<source>: <key.path>: <value> <what is wrong> (<what is allowed>)``.
    """
    if cfg is not None and not isinstance(cfg, Mapping):
        raise ConfigError(f"{_where(source)}top level must be a mapping, got {type(cfg).__name__}")
    inst = _plain(cfg or {})
    _validate(inst, _schema(), _where(source))
    return typed("", inst)


def validate_section(path: str, sec: Mapping[str, Any] | None) -> dict[str, Any]:
    """Validate one section (dotted path, e.g. ``preprocess`` or ``simulate.sensors.radar``)
    and return a defaulted copy; errors name the full key path."""
    parts = [p for p in path.split(".") if p]
    root = _schema()
    try:
        node: dict[str, Any] = dict(_subschema(path))
    except KeyError:
        allowed = ", ".join(root.get("properties") or {})
        raise ConfigError(f"{path}: unknown section (allowed: {allowed})") from None
    inst: Any = _plain(sec if sec is not None else {})
    if inst == {} and node.get("type") == "object" and not node.get("required"):
        return default_at(path)    # nothing to check: the defaults (no jsonschema import)
    for part in reversed(parts):
        node = {"type": "object", "properties": {part: node}}
        inst = {part: inst}
    node["$defs"] = root.get("$defs", {})
    _validate(inst, node, "")
    for part in parts:
        inst = inst[part]
    return inst


def read_text_file(path: str | os.PathLike, what: str, *, source: str | None = None) -> str:
    """The text of a config or manifest file, or one :class:`ConfigError` line saying why not.

    UTF-8, with a leading byte-order mark dropped (a spreadsheet or Windows editor saving "UTF-8"
    writes one; kept, it would become part of the first key or column name).

    Parameters
    ----------
    path : path-like
        The file.
    what : str
        What it is, for the message (``"config"``, ``"manifest"``).
    source : str, optional
        How the message names the file (default: ``path`` as given).

    Raises
    ------
    ConfigError
        ``<source>: <what> file not found``, ``<source>: cannot read the <what>: <reason>`` or
        ``<source>:<line>: not UTF-8 text (byte 0x..); save the <what> as UTF-8``.
    """
    src = str(path) if source is None else source
    try:
        return Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{src}: {what} file not found") from None
    except OSError as exc:
        raise ConfigError(f"{src}: cannot read the {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise ConfigError(f"{src}:{line}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x}); save the "
                          f"{what} as UTF-8") from None


def default_config_path() -> Path:
    """The config a command reads without ``--config``: ``datasets/config.yaml`` of the current
    folder when there is one (where Snakemake, started there, reads it too), else this checkout's
    :data:`DEFAULT_CONFIG`. Without the first, a user working in a project folder of their own
    would silently get the repository's dataset settings."""
    local = Path("datasets") / "config.yaml"
    return local if local.is_file() else DEFAULT_CONFIG


def load_config(path: str | os.PathLike | None = None) -> dict[str, Any]:
    """Load, validate and default the dataset config (default :func:`default_config_path`)."""
    p = Path(path) if path else default_config_path()
    return validate_config(read_config_file(p), source=p)


def read_config_file(path: str | os.PathLike) -> Any:
    """The YAML of a config file as read (not validated), or one :class:`ConfigError` line: the
    file unreadable, not UTF-8, not YAML, or a key repeated in one mapping (YAML would keep the
    last silently). The workflow calls it on ``datasets/config.yaml`` before Snakemake reads it
    and on every ``--configfile`` for what Snakemake's own reader lets pass (a repeated key: it
    keeps the last). A YAML syntax error in a ``--configfile`` stops Snakemake itself, before the
    workflow runs, with its own message; ``uavpipe config --config FILE`` names its line."""
    p = Path(path)
    text = read_text_file(p, "config")
    try:
        doc = yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}:{_yaml_where(exc)} invalid YAML: {_yaml_problem(exc)}") from None
    loop = _self_reference(doc)
    if loop is not None:
        # an alias inside its own anchor (`a: &x [*x]`) loads as a list that holds itself:
        # every later walk of the config would recurse without end
        raise ConfigError(f"{p}: {loop or 'top level'}: a YAML alias refers to the value that contains it "
                          "(a recursive anchor)")
    return doc


def _self_reference(x: Any, where: str = "", inside: tuple[int, ...] = ()) -> str | None:
    """The dotted key of the first mapping or list that contains itself, or None."""
    if not isinstance(x, (dict, list)):
        return None
    if id(x) in inside:
        return where
    inside = inside + (id(x),)
    items = x.items() if isinstance(x, dict) else enumerate(x)
    for k, v in items:
        found = _self_reference(v, f"{where}.{k}" if where else str(k), inside)
        if found is not None:
            return found
    return None


def _yaml_where(exc: Exception) -> str:
    """``line:column:`` (1-based) of a YAML error, where it has a mark."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    return f"{mark.line + 1}:{mark.column + 1}:" if mark is not None else ""


def _yaml_problem(exc: Exception) -> str:
    """The YAML error in words, without the reader's ``in "<unicode string>", line ...`` marks
    (the location is given once, in front)."""
    parts = [getattr(exc, "context", None), getattr(exc, "problem", None)]
    words = "; ".join(str(x) for x in parts if x) or str(exc)
    return " ".join(words.split())


def command_line_overrides(cli: Mapping[str, Any] | None) -> dict[str, Any]:
    """Snakemake ``--config key=VALUE`` overrides with their scalars typed as the config file's.

    Snakemake reads a nested ``VALUE`` (``studies='{pf: {n_particles: 500}}'``) with YAML's
    BaseLoader, which keeps every scalar a string, so ``true`` or ``500`` would fail the schema
    as ``'true'``/``'500'``. Each string scalar is read again with the loader of
    :func:`load_config`, so an override means what the same text means in
    ``datasets/config.yaml`` (``true`` a boolean, ``500`` an integer, ``null`` null, a path a
    string); top-level ``key=VALUE`` numbers, which Snakemake already types, pass unchanged.
    """

    def typed(v: Any) -> Any:
        if isinstance(v, Mapping):
            return {k: typed(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [typed(x) for x in v]
        if isinstance(v, str):
            try:
                return yaml.load(v, Loader=_Loader) if v.strip() else v
            except yaml.YAMLError:
                return v        # not a YAML scalar on its own (e.g. 'a: b: c'): the schema names it
        return v

    return typed(dict(cli or {}))


def section(cfg: Mapping[str, Any] | None, name: str) -> dict[str, Any]:
    """One section (``ingest``, ``simulate``, ``preprocess``, ``hmm``, ...; a dotted name such
    as ``simulate.sensors`` is a section inside one), validated and defaulted (all defaults when
    absent)."""
    if cfg is not None and not isinstance(cfg, Mapping):
        raise ConfigError(f"config: top level must be a mapping, got {type(cfg).__name__}")
    node: Any = cfg or {}
    for part in name.split("."):  # the user's value at the dotted path, not the bare default
        node = node.get(part) if isinstance(node, Mapping) else None
    return validate_section(name, node)


def _plain(x: Any) -> Any:
    """Deep copy into plain dicts/lists (YAML and Snakemake namedlists alike)."""
    if isinstance(x, Mapping):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, datetime.date):
        # YAML reads an unquoted 2026-01-02T12:00:00Z as a timestamp (Snakemake's loader and
        # --config alike); the schema's times are ISO 8601 strings, which this gives back
        return x.isoformat()
    return x


# --- one-line error messages -------------------------------------------------------------------

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TYPE_WORDS = {"number": "a number", "integer": "an integer", "string": "a string",
               "boolean": "true/false", "array": "a list", "object": "a mapping", "null": "null"}


def key_path(parts) -> str:
    """``['preprocess', 'butterworth', 'baro.alt_rel_m', 'order']`` ->
    ``preprocess.butterworth['baro.alt_rel_m'].order``."""
    out = ""
    for p in parts:
        if isinstance(p, int):
            out += f"[{p}]"
        elif _IDENT.match(str(p)):
            out += f".{p}" if out else str(p)
        else:
            out += f"[{str(p)!r}]"
    return out


def _describe(schema_: Mapping[str, Any], root: Mapping[str, Any]) -> str:
    s = _resolve(schema_, root)
    if "const" in s:
        return repr(s["const"])
    if "enum" in s:
        return "one of " + ", ".join(str(v) for v in s["enum"])
    if "oneOf" in s or "anyOf" in s:
        return " or ".join(_describe(b, root) for b in s.get("oneOf", s.get("anyOf", ())))
    t = s.get("type")
    ts = t if isinstance(t, list) else [t] if t else []
    words = [_TYPE_WORDS.get(x, x) for x in ts]
    lim = []
    for k, op in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
                  ("exclusiveMaximum", "<")):
        if k in s:
            lim.append(f"{op} {s[k]}")
    if "minItems" in s and s.get("minItems") == s.get("maxItems"):
        lim.append(f"of {s['minItems']}")
    desc = " or ".join(words) or "a value"
    return desc + (" " + ", ".join(lim) if lim else "")


def _value(v: Any) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


#: numbers YAML 1.1 leaves as text: an exponent without a dot in the mantissa (1e-4, 2E3)
_SCI_NUMBER = re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$")


def _sci_fix(text: str) -> str:
    """``1e-4`` -> ``1.0e-4``: the same number in the form YAML 1.1 reads as a float."""
    m, e = re.split("[eE]", text, maxsplit=1)
    return f"{m}.0e{e}"


def _explain(err, root: Mapping[str, Any]) -> tuple[int, tuple, str]:
    """(rank, path key, one-line message) of a jsonschema error; rank 0 = unknown key."""
    path = list(err.absolute_path)
    kw = err.validator
    inst = err.instance
    sch = err.schema if isinstance(err.schema, Mapping) else {}
    order = tuple(str(p) for p in path)
    at = key_path(path)
    pre = f"{at}: " if at else ""
    if kw == "additionalProperties" and err.validator_value is False:
        props = list((sch.get("properties") or {}).keys())
        pats = list((sch.get("patternProperties") or {}).keys())
        extra = [k for k in inst if k not in props and not any(re.search(p, k) for p in pats)]
        key = extra[0] if extra else "?"
        what = "unknown section" if not path else "unknown key"
        return 0, order + (str(key),), f"{key_path(path + [key])}: {what} (allowed: {', '.join(props)})"
    if kw in ("oneOf", "anyOf"):
        branches = err.validator_value
        # the branches of the right kind (no type/const/enum error on the value itself)
        fitting = []
        for i, b in enumerate(branches):
            sub = [c for c in err.context if c.relative_schema_path and c.relative_schema_path[0] == i]
            kinds = {c.validator for c in sub if not list(c.relative_path)}
            if sub and not kinds & {"type", "const", "enum"}:
                fitting.append(sub)
        if len(fitting) == 1:
            return min((_explain(c, root) for c in fitting[0]), key=lambda r: r[:2])
        if kw == "oneOf" and not err.context:
            return 1, order, f"{pre}{_value(inst)} matches more than one of {_describe(sch, root)}"
        return 1, order, f"{pre}{_value(inst)} is not {_describe(sch, root)}"
    if kw == "type":
        if isinstance(inst, float) and not math.isfinite(inst):
            return 1, order, f"{pre}{_value(inst)} is not a finite number"
        hint = ""
        if isinstance(inst, str) and _SCI_NUMBER.match(inst.strip()):
            # YAML 1.1 (PyYAML, Snakemake) reads a float only with a dot before the exponent
            hint = f" (YAML reads {inst} as text: write {_sci_fix(inst.strip())})"
        return 1, order, f"{pre}{_value(inst)} is not {_describe({'type': err.validator_value}, root)}{hint}"
    if kw == "enum":
        return 1, order, f"{pre}{_value(inst)} is not one of {', '.join(map(str, err.validator_value))}"
    if kw == "const":
        return 1, order, f"{pre}{_value(inst)} is not {err.validator_value!r}"
    if kw in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        op = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}[kw]
        return 1, order, f"{pre}{_value(inst)} is out of range (must be {op} {err.validator_value})"
    if kw in ("minItems", "maxItems"):
        n = err.validator_value
        need = f"at least {n}" if kw == "minItems" else f"at most {n}"
        if sch.get("minItems") == sch.get("maxItems"):
            need = f"exactly {n}"
        return 1, order, f"{pre}{_value(inst)} has {len(inst)} item(s), needs {need}"
    if kw == "required":
        missing = [k for k in err.validator_value if k not in inst]
        key = missing[0] if missing else "?"
        return 1, order + (str(key),), f"{key_path(path + [key])}: missing required key"
    if kw == "propertyNames":
        bad = [k for k in inst if any(c.instance == k for c in err.context)] or ["?"]
        pn = err.validator_value or {}
        what = pn.get("title") or f"a name matching {pn.get('pattern', '')}"
        return 1, order + (str(bad[0]),), f"{pre}{bad[0]!r} is not an allowed name (must be {what})"
    if kw == "pattern" and not isinstance(err.instance, str):
        return 1, order, f"{pre}{_value(inst)} is not a string"
    if kw == "pattern":
        what = sch.get("title") or f"a string matching {err.validator_value}"
        return 1, order, f"{pre}{_value(inst)} is not {what}"
    if kw == "uniqueItems":
        return 1, order, f"{pre}{_value(inst)} has duplicate items"
    if kw == "minProperties":
        return 1, order, f"{pre}must not be empty"
    return 1, order, f"{pre}{' '.join(err.message.split())}"


# --- the one dataclass builder -----------------------------------------------------------------

_MISSING = object()


def cfield(section_path: str, key: str | tuple[str, ...] | Callable[[Mapping], Any],
           *, default_path: str | None = None, convert: Callable[[Any], Any] | None = None,
           **field_kw) -> Any:
    """A dataclass field whose default is the schema's and whose value :func:`build` takes from
    ``key`` of the section it is given.

    Parameters
    ----------
    section_path : str
        Dotted schema path of the section the dataclass is built from (``simulate``).
    key : str, tuple of str or callable
        Dotted key inside the section (usually the field name); a tuple of keys gives a tuple
        of their values; a callable takes the section.
    default_path : str, optional
        Schema path of the default where ``key`` is a callable.
    convert : callable, optional
        Turns the raw value (and the raw default) into the field's value (e.g. units).
    """
    meta = dict(field_kw.pop("metadata", None) or {})
    meta["config_key"] = key
    meta["config_section"] = section_path
    if convert is not None:
        meta["config_convert"] = convert
    if callable(key):
        if default_path is None:
            raise TypeError("cfield: a callable key needs default_path")
        dflt = default_at(default_path)
    elif isinstance(key, tuple):
        dflt = tuple(default_at(f"{section_path}.{k}") for k in key)
    else:
        dflt = default_at(f"{section_path}.{key}")
    if convert is not None:
        dflt = convert(dflt)
    dflt = _frozen(dflt)
    if isinstance(dflt, (dict, list, set)):
        return dataclasses.field(default_factory=functools.partial(copy.deepcopy, dflt),
                                 metadata=meta, **field_kw)
    return dataclasses.field(default=dflt, metadata=meta, **field_kw)


def _frozen(v: Any) -> Any:
    """Lists -> tuples (a list default would be a shared mutable); a dict default stays as it
    is (deep-copied per instance), as a dict built from the YAML does."""
    if isinstance(v, list):
        return tuple(_frozen(x) for x in v)
    return v


def typed(path: str, value: Any) -> Any:
    """``value`` with its numbers shaped by the schema types at ``path`` (``number`` -> float,
    ``integer`` -> int) and its declared keys in schema order, recursively: dict-valued
    dataclass fields see the same types whether the value came from the YAML (``10``) or from
    the schema default (``10.0``), and a workflow job's parameters read the same whether a
    setting was written out, reordered or left to its default (Snakemake compares their repr)."""
    root = _schema()

    def walk(node: Mapping[str, Any], v: Any) -> Any:
        node = _resolve(node, root)
        if isinstance(v, bool) or v is None:
            return v
        if isinstance(v, dict):
            props = node.get("properties") or {}
            addl = node.get("additionalProperties")
            # declared keys in the schema's order, then the user's own names (model sets,
            # vehicles...) in the order given: the same settings give the same mapping
            keys = [k for k in props if k in v] + [k for k in v if k not in props]
            return {k: walk(props[k] if k in props else addl if isinstance(addl, Mapping) else {}, v[k])
                    for k in keys}
        if isinstance(v, list):
            items = node.get("items")
            return [walk(items if isinstance(items, Mapping) else {}, x) for x in v]
        t = node.get("type")
        ts = set(t if isinstance(t, list) else [t] if t else [])
        for b in [*node.get("oneOf", ()), *node.get("anyOf", ())]:
            bt = _resolve(b, root).get("type")
            ts |= set(bt if isinstance(bt, list) else [bt] if bt else [])
        if isinstance(v, (int, float)):
            if "number" in ts and "integer" not in ts:
                return float(v)
            if "integer" in ts and "number" not in ts and float(v).is_integer():
                return int(v)
        return v

    return walk(_subschema(path), value)


def _lookup(sec: Mapping[str, Any], key: Any) -> Any:
    if callable(key):
        return key(sec)
    if isinstance(key, tuple):
        vals = tuple(_lookup(sec, k) for k in key)
        return _MISSING if any(v is _MISSING for v in vals) else vals
    cur: Any = sec
    for part in str(key).split("."):
        if not isinstance(cur, Mapping) or part not in cur:
            return _MISSING
        cur = cur[part]
    return cur


def _coerce(tp: Any, v: Any) -> Any:
    """Shape a validated YAML value to a type hint (nested dataclasses, tuples, dicts, Optional)."""
    if tp is Any or tp is None:
        return copy.deepcopy(v)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if dataclasses.is_dataclass(tp) and isinstance(v, Mapping):
        return build(tp, v)
    if origin in (typing.Union, types.UnionType):
        if v is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            if _fits(a, v):
                return _coerce(a, v)
        return copy.deepcopy(v)
    if origin is typing.Literal:
        return v
    if origin is tuple or tp is tuple:
        if not isinstance(v, (list, tuple)):
            return v
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], x) for x in v)
        if args and len(args) == len(v):
            return tuple(_coerce(a, x) for a, x in zip(args, v))
        return tuple(_coerce(Any, x) for x in v)
    if origin is list or tp is list:
        return [_coerce(args[0] if args else Any, x) for x in v]
    if origin in (dict, Mapping) or tp in (dict, Mapping) or origin is typing.Mapping:
        if not isinstance(v, Mapping):
            return copy.deepcopy(v)
        vt = args[1] if len(args) == 2 else Any
        return {k: _coerce(vt, x) for k, x in v.items()}
    if tp is float and isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v)
    if tp is int and isinstance(v, (int, float)) and not isinstance(v, bool) and float(v).is_integer():
        return int(v)
    if tp is str and isinstance(v, str):
        return v
    if tp is bool and isinstance(v, bool):
        return v
    return copy.deepcopy(v)


def _fits(tp: Any, v: Any) -> bool:
    origin = typing.get_origin(tp) or tp
    if tp is Any:
        return True
    if dataclasses.is_dataclass(tp):
        return isinstance(v, Mapping)
    if origin is typing.Literal:
        return v in typing.get_args(tp)
    if origin in (tuple, list):
        return isinstance(v, (list, tuple))
    if origin in (dict, Mapping):
        return isinstance(v, Mapping)
    if tp is float:
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    if tp is int:
        return isinstance(v, int) and not isinstance(v, bool)
    if isinstance(origin, type):
        return isinstance(v, origin)
    return False


def build(cls: type, sec: Mapping[str, Any] | None, /, **values: Any):
    """Build a (nested) frozen dataclass from a validated config section.

    Each init field takes, in order: ``values[name]`` (per-call values, e.g. the master seed),
    else the section's value at the field's ``config_key`` (:func:`cfield`; default the field
    name), shaped by the type hint (nested dataclasses from mappings, tuples from lists, dicts,
    ``Optional``, ``Literal``) or the field's ``convert``; a key absent from the section leaves
    the dataclass default, which is the schema's. Fields with ``metadata={"config_key": None}``
    (or ``init=False``) are not read from the section.
    """
    hints = typing.get_type_hints(cls)
    sec = sec or {}
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.name in values:
            kw[f.name] = values[f.name]
            continue
        key = f.metadata.get("config_key", f.name)
        if key is None:
            continue
        raw = _lookup(sec, key)
        if raw is _MISSING:
            continue
        conv = f.metadata.get("config_convert")
        kw[f.name] = conv(copy.deepcopy(raw)) if conv else _coerce(hints.get(f.name, Any), raw)
    unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
    if unknown:
        raise TypeError(f"build({cls.__name__}): no field(s) {sorted(unknown)}")
    return cls(**kw)


if __name__ == "__main__":  # python -m pipeline.config: the key reference of datasets/README.md
    print(markdown_reference(), end="")
