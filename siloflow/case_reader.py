"""Reading a case file, below the case schema: at most ``MAX_CASE_BYTES`` of a regular file, parsed
with a hardened safe YAML loader (unique keys, no aliases or tags, depth at most ``MAX_CASE_DEPTH``),
validated by the schema its caller passes in, and any problem turned into a ``CaseError`` listing
each with its field path (or its line, for YAML errors).

The schema is passed in (``siloflow.case_file`` passes ``Case``; so does ``Case.from_yaml``), so
this module imports nothing of the schema and the schema can read files through it.
"""
from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import ValidationError

from .errors import CaseError
from .silos.registry import SILO_KINDS, silo_kind


#: case files larger than this are refused unread (the largest real case is a few kB)
MAX_CASE_BYTES = 1_000_000
#: deepest nesting of YAML lists and mappings accepted (a case nests at most 5; the composer and
#: the validation recurse per level, so 400 levels would exhaust Python's stack)
MAX_CASE_DEPTH = 32


def _short(value, limit: int = 60) -> str:
    """``repr`` of a value cut to ``limit`` characters (a 4301-digit number stays readable)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


class _UniqueKeyLoader(yaml.SafeLoader):
    """Safe YAML loader that refuses duplicate keys, aliases (no 'billion laughs'), collection
    keys (``? [a, b]``) and nesting deeper than ``MAX_CASE_DEPTH``; a scalar that its tag cannot
    convert (``!!int "abc"``, ``2020-13-45``, a 4301-digit integer) is a ``ConstructorError`` at
    the scalar's line instead of a bare ``ValueError``."""

    _depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.events.AliasEvent):
            _refuse_alias(self)
        collection = self.check_event(yaml.events.SequenceStartEvent, yaml.events.MappingStartEvent)
        self._depth += collection
        try:
            if self._depth > MAX_CASE_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested deeper than {MAX_CASE_DEPTH} levels", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= collection

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep=deep)
        except yaml.YAMLError:
            raise
        except (ValueError, TypeError, ArithmeticError, LookupError, AttributeError) as exc:
            value = node.value if isinstance(node, yaml.ScalarNode) else node.id
            tag = node.tag.rsplit(":", 1)[-1]
            # a ValueError's text says what is wrong ("month must be in 1..12"); others are internals
            detail = str(exc).split(";")[0][:120] if type(exc) is ValueError else ""
            detail = "" if detail.startswith(("could not convert", "invalid literal")) else detail
            raise yaml.constructor.ConstructorError(
                None, None, f"{_short(value)} is not a valid {tag}" + (f" ({detail})" if detail else ""),
                node.start_mark) from None


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            raise yaml.constructor.ConstructorError(
                None, None, "a mapping key must be a plain name, not a list or mapping", key_node.start_mark)
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {_short(key)}", key_node.start_mark)
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


def _refuse_alias(loader, *args, **kwargs):
    event = loader.peek_event()
    raise yaml.composer.ComposerError(None, None, "YAML aliases (*name) are not allowed in case files",
                                      event.start_mark)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _field_path(loc) -> str:
    parts = []
    for item in loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        elif item in (*SILO_KINDS, "spheres", "polydisperse_spheres", "clumps") and parts:
            continue  # discriminator tag pydantic inserts into the path
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts) or "(top level)"


def validation_problems(error: ValidationError) -> list[tuple[str, str]]:
    """Turn a pydantic ValidationError into ``(field path, plain sentence)`` pairs."""
    problems = []
    for err in error.errors():
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not part of the case schema)"
        elif err["type"] == "string_pattern_mismatch":
            msg = ("only letters, digits and _ . - are allowed (max 64 characters, not starting "
                   f"with . or -); got {str(err.get('input'))[:80]!r}")
        elif err["type"] == "finite_number":
            msg = "must be a finite number (NaN and infinity are refused)"
        elif err["type"] == "int_type":
            got = err.get("input")
            msg = ("must be a whole number, not true/false" if isinstance(got, bool) else
                   f"must be a whole number (got {_short(got)})")
        msg = msg.removeprefix("Value error, ")
        problems.append((_field_path(err["loc"]), msg))
    return problems


def validate_case(schema, data, source: str = "case"):
    """Validate a mapping with the case schema ``schema`` (``siloflow.case.Case``); raise
    ``CaseError`` listing every problem."""
    if not isinstance(data, dict):
        raise CaseError([("(top level)", "the case file must be a YAML mapping of sections")], source)
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise CaseError(validation_problems(exc), source) from None


def locate_inserts(case, base: Path):
    """The case (a validated ``Case``) with its inserts' files, and a mesh silo's (``geometry.files``),
    as absolute paths, relative ones taken from ``base`` (the case file's folder). The files are read
    and checked when the run is planned."""
    def located(file: str) -> str:
        path = Path(file)
        return str((path if path.is_absolute() else base / path).resolve())

    update = {}
    if case.inserts:
        update["inserts"] = [ins.model_copy(update={"file": located(ins.file)}) for ins in case.inserts]
    if silo_kind(case.geometry.kind).reads_files:
        update["geometry"] = case.geometry.model_copy(update={"files": [located(f) for f in case.geometry.files]})
    return case.model_copy(update=update) if update else case


def read_case_bytes(path) -> bytes:
    """The bytes of a case file, at most ``MAX_CASE_BYTES``: regular files only (a FIFO, a device
    such as /dev/zero or a directory is refused before it is read, never hangs, never read whole;
    ``siloflow.atomic_files.read_regular_bytes``). Raises ``CaseError``."""
    from .atomic_files import read_regular_bytes
    try:
        return read_regular_bytes(path, MAX_CASE_BYTES, "a case")
    except ValueError as exc:
        raise CaseError([("(file)", str(exc))], str(path)) from None


def parse_case_yaml(raw: bytes, source: str = "case"):
    """Parse case-file bytes with the safe loader; any problem is a ``CaseError`` naming the line
    and column where the parser knows them."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise CaseError([("(file)", f"not UTF-8 text (line {line}, byte {exc.start + 1})")], source) from None
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise CaseError([("(yaml)", f"{where}{problem}")], source) from None
    except (RecursionError, MemoryError):
        raise CaseError([("(yaml)", "nested too deeply or too large to read")], source) from None
    except (ValueError, TypeError, ArithmeticError, LookupError, AttributeError) as exc:
        raise CaseError([("(yaml)", f"cannot be read as YAML ({type(exc).__name__}: {str(exc)[:120]})")],
                        source) from None


def read_case(schema, path):
    """Read a YAML case file and validate it with ``schema`` (``siloflow.case.Case``), raising
    ``CaseError`` on any problem; the inserts' files are located relative to the case file."""
    path = Path(path)
    data = parse_case_yaml(read_case_bytes(path), str(path))
    return locate_inserts(validate_case(schema, data, str(path)), path.parent)
