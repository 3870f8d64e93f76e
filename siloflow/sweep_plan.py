"""The variants of a sweep: one case over ``--set`` values and seeds, and their fill groups.

A sweep is the cartesian product of the ``--set PATH=V1,V2,...`` values (:func:`parse_set`) times
``seeds`` seeds (:func:`expand`); each combination is a :class:`Variant`, a validated case named
``<case>-<index>``. Variants whose settled beds are the same (one
:func:`siloflow.fill_cache.fill_key`) form a fill group (:func:`group_by_fill`): its first variant
computes the fill and publishes it in the fill cache, the others start from it.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Optional

import yaml

from .case import Case
from .case_file import case_from_dict
from .errors import CaseError, SetupError

#: most values one ``--set`` may list
MAX_SET_VALUES = 1000
#: most variants one sweep may expand into (values x seeds)
MAX_VARIANTS = 10000
#: a segment of a ``--set`` field path
FIELD_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: a float as YAML 1.2 reads it; PyYAML (YAML 1.1) leaves ``1e-3`` and ``5.0e6`` strings
YAML12_FLOAT = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")
#: longest case name (``siloflow.case.SAFE_NAME_PATTERN``)
MAX_NAME_LENGTH = 64
#: progress(stage, done, total) while a sweep is prepared or written: "planning", "writing"
StageProgress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: its position ``index`` (0..n-1), case ``name`` (``<case>-<index>``),
    the ``--set`` ``values`` ({field path: value}), ``seed``, the case mapping ``data`` (written
    to ``cases/<name>.yaml``) and its validated ``case``."""

    index: int
    name: str
    values: dict
    seed: int
    data: dict
    case: Case


# ------------------------------------------------------------------ --set and the variants
def _shown(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _scalar(item: str, spec: str):
    """One ``--set`` value as a YAML scalar (numbers in YAML 1.2's spelling too)."""
    text = item.strip()
    if not text:
        raise SetupError(f"--set {spec}: an empty value (two commas, or nothing after '=')")
    try:
        value = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError) as exc:
        problem = getattr(exc, "problem", None) or exc
        raise SetupError(f"--set {spec}: {_shown(text)!r} is not a YAML value ({problem})") from None
    if isinstance(value, str) and value == text and YAML12_FLOAT.fullmatch(text):
        value = float(text)
    if value is not None and not isinstance(value, (bool, int, float, str)):
        raise SetupError(f"--set {spec}: {_shown(text)!r} is a {type(value).__name__}; a value must be a number, "
                         "true/false, null or a string (quote it: '\"...\"')")
    return value


def parse_set(spec: str) -> tuple[str, list]:
    """``"geometry.orifice_radius=0.006,0.008"`` -> ``("geometry.orifice_radius", [0.006, 0.008])``.

    Each value is read as a YAML scalar: numbers (``1e-3`` too), ``true``/``false``, ``null``,
    strings. Raises ``SetupError`` naming the ``--set`` for an empty path or value, a path segment
    that is not a field name (``[A-Za-z_][A-Za-z0-9_]*``), a value given twice or more than
    ``MAX_SET_VALUES`` values.
    """
    shown = _shown(spec)
    path, sep, text = spec.partition("=")
    path = path.strip()
    if not sep:
        raise SetupError(f"--set {shown}: expected PATH=V1,V2,... (e.g. geometry.orifice_radius=0.006,0.008)")
    if not path:
        raise SetupError(f"--set {shown}: no field path before '='")
    for segment in path.split("."):
        if not FIELD_NAME.fullmatch(segment):
            raise SetupError(f"--set {shown}: {segment!r} in {_shown(path)!r} is not a field name (letters, "
                             "digits and _, not starting with a digit; sections joined by '.')")
    items = text.split(",")
    if len(items) > MAX_SET_VALUES:
        raise SetupError(f"--set {shown}: {len(items)} values; at most {MAX_SET_VALUES}")
    values = [_scalar(item, shown) for item in items]
    seen = set()
    for value in values:
        if (type(value), value) in seen:
            raise SetupError(f"--set {shown}: the value {value!r} is given twice")
        seen.add((type(value), value))
    return path, values


def _check_paths(sets: list[tuple[str, list]], seeds: int) -> None:
    paths = [path for path, _ in sets]
    for i, path in enumerate(paths):
        if path == "name":
            raise SetupError("--set name: a sweep names its variants itself (<case name>-<index>)")
        if path == "seed" and seeds > 1:
            raise SetupError("--set seed and --seeds: give the seeds one way (--set seed=1,2,3 or --seeds 3)")
        for other in paths[:i]:
            if other == path:
                raise SetupError(f"--set {path} is given twice: list all its values in one --set")
            if path.startswith(other + ".") or other.startswith(path + "."):
                raise SetupError(f"--set {other} and --set {path}: one is inside the other")


def _base_name(name) -> str:
    """The case name as the stem of variant names: ``siloflow.case.SAFE_NAME_PATTERN``'s alphabet, other
    characters as ``_``, no leading ``.`` or ``-`` ('sweep' if nothing is left)."""
    text = re.sub(r"[^A-Za-z0-9_.-]", "_", name if isinstance(name, str) else "")
    return text.lstrip(".-") or "sweep"


def variant_name(base: str, index: int) -> str:
    """``<base>-<index:03d>``, the base cut so that the name fits ``siloflow.case.SAFE_NAME_PATTERN`` (64 characters)."""
    suffix = f"-{index:03d}"
    return _base_name(base)[:MAX_NAME_LENGTH - len(suffix)] + suffix


def _set_field(data: dict, path: str, value, source: str) -> None:
    """Set ``value`` at the dotted ``path`` of ``data``, making missing sections."""
    node = data
    keys = path.split(".")
    for depth, key in enumerate(keys[:-1]):
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            where = ".".join(keys[:depth + 1])
            raise CaseError([(where, f"is a {type(node).__name__}, not a section: --set {path} cannot set a "
                                     "field inside it")], source)
    node[keys[-1]] = value


def _made_by(values: dict, seed) -> str:
    given = ", ".join(f"--set {path}={json.dumps(value)}" for path, value in values.items() if path != "seed")
    return (given + ", " if given else "") + f"seed {seed}"


def expand(case_data: dict, sets: list[tuple[str, list]], seeds: int = 1) -> list[Variant]:
    """The sweep's variants: every combination of the ``--set`` values (the last ``--set``
    varying fastest) times ``seeds`` seeds, seed k being the case's ``seed`` (or the ``--set
    seed`` value) + k. Each is a deep copy of ``case_data`` with the values at their dotted
    paths (missing sections made), named ``<case name>-<index:03d>`` and validated.

    Raises
    ------
    SetupError
        for ``seeds`` < 1, a path given twice or inside another, ``--set name``, ``--set seed``
        with ``seeds`` > 1, or more than ``MAX_VARIANTS`` variants.
    CaseError
        for the first variant that does not validate: each problem names the field and the
        ``--set`` values and seed that made it.
    """
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise SetupError(f"--seeds {seeds!r}: the number of seeds must be a whole number >= 1")
    if not isinstance(case_data, dict):
        raise CaseError([("(top level)", "the case file must be a YAML mapping of sections")], "sweep")
    _check_paths(sets, seeds)
    count = math.prod(len(values) for _, values in sets) * seeds
    if count > MAX_VARIANTS:
        raise SetupError(f"the sweep expands into {count} runs ({' x '.join(str(len(v)) for _, v in sets)} values "
                         f"x {seeds} seeds); at most {MAX_VARIANTS}")
    paths = [path for path, _ in sets]
    base = case_data.get("name")
    variants = []
    for combination in itertools.product(*(values for _, values in sets)):
        values = dict(zip(paths, combination))
        for k in range(seeds):
            index = len(variants)
            name = variant_name(base, index)
            source = f"sweep variant {name}"
            data = copy.deepcopy(case_data)
            for path, value in values.items():
                _set_field(data, path, value, source)
            seed = data.get("seed", Case.model_fields["seed"].default)
            if k:
                if isinstance(seed, bool) or not isinstance(seed, int):
                    raise CaseError([("seed", f"is {seed!r}: --seeds adds to it, so it must be a whole number")],
                                    source)
                seed += k
            data["seed"], data["name"] = seed, name
            try:
                case = case_from_dict(data, source)
            except CaseError as exc:
                raise in_variant(exc, name, values, seed) from None
            variants.append(Variant(index, name, values, seed, data, case))
    return variants


def in_variant(exc: CaseError, name: str, values: dict, seed) -> CaseError:
    """``exc`` with each problem saying which variant, ``--set`` values and seed made it."""
    made = _made_by(values, seed)
    return CaseError([(path, f"{message} (from {made})") for path, message in exc.problems],
                     f"sweep variant {name}")



# ------------------------------------------------------------------ fill groups
def sweep_engine(variants: list[Variant], need_binary: bool = True):
    """The engine the variants name (one for all), for their fill keys. Its version is asked
    once (``fill_key_parts`` asks for it per plan). Without the binary on this machine (a Slurm
    sweep written on a login node), ``need_binary=False`` keys with a stand-in version: the
    grouping is the same, since every variant has it. Raises ``SetupError``."""
    from .engine import get_engine
    names = sorted({v.case.engine.name for v in variants})
    if len(names) != 1:
        raise SetupError(f"one sweep runs one engine; its variants name {', '.join(names) or 'none'} (engine.name)")
    engine = get_engine(names[0])
    try:
        version = engine.version()
    except SetupError:
        if need_binary:
            raise
        version = "(not installed where the sweep was written)"
    engine.version = lambda: version        # the binary does not change during the sweep
    return engine


@contextmanager
def _shared_meshes():
    """Within the block, ``derive`` computes the walls of each distinct silo once: it takes
    ``siloflow.geometry.silo_meshes`` when called, here memoised by what shapes the walls (the
    plan's silo, the band boundaries and sectors, the counting disc, whether the side walls
    are sensors, and a silo from STL's walls). Most of a plan's time is its meshes, the same for every variant of a silo."""
    from . import geometry as meshes
    original = meshes.silo_meshes
    memo: dict[str, list] = {}

    def shared(silo, band_bounds, sectors, outlet_z, outlet_radius, sensors=True, container=None):
        walls = hashlib.sha256(container.triangles.tobytes()).hexdigest() if container is not None else None
        key = json.dumps([silo.model_dump(mode="json"), list(band_bounds), sectors, outlet_z, outlet_radius, sensors,
                          walls], sort_keys=True)
        if key not in memo:
            memo[key] = original(silo, band_bounds, sectors, outlet_z, outlet_radius, sensors, container)
        return list(memo[key])

    meshes.silo_meshes = shared
    try:
        yield
    finally:
        meshes.silo_meshes = original


def _but_name_and_seed(v: Variant) -> str:
    """The variant's case fields without ``name`` and ``seed``, as text: variants that agree on
    it have one plan but for those two (``derive`` only copies them into the plan)."""
    return json.dumps({k: x for k, x in v.data.items() if k not in ("name", "seed")}, sort_keys=True, default=str)


def group_by_fill(variants: list[Variant], engine, progress: Optional[StageProgress] = None) -> dict[str, list[Variant]]:
    """The variants by fill key (``siloflow.fill_cache.fill_key`` of each one's run plan on
    ``engine``), in order of first appearance, each group in variant order. A plan is derived
    once per distinct case but its name and seed (the seeds' plans are copies with theirs), and
    the walls once per distinct silo (:func:`_shared_meshes`). ``progress("planning", done,
    total)`` is told of each variant. Raises the ``CaseError`` of a variant whose plan cannot be
    made, naming its ``--set`` values."""
    from .derived import derive
    from .fill_cache import fill_key
    groups: dict[str, list[Variant]] = {}
    plans: dict[str, object] = {}
    with _shared_meshes():
        for done, v in enumerate(variants, 1):
            same = _but_name_and_seed(v)
            plan = plans.get(same)
            try:
                if plan is None:
                    plan = plans[same] = derive(v.case)
            except CaseError as exc:
                raise in_variant(exc, v.name, v.values, v.seed) from None
            if (plan.name, plan.seed) != (v.case.name, v.case.seed):
                plan = plan.model_copy(update={"name": v.case.name, "seed": v.case.seed})
            groups.setdefault(fill_key(plan, engine), []).append(v)
            if progress is not None:
                progress("planning", done, len(variants))
    return groups


def check_engine(variants: list[Variant], engine) -> None:
    """Refuse, before anything runs, a variant the engine cannot run (``Engine.check``)."""
    from .engine.base import check_case
    for v in variants:
        try:
            check_case(v.case, engine)
        except CaseError as exc:
            raise in_variant(exc, v.name, v.values, v.seed) from None


def variant_keys(groups: dict[str, list[Variant]], variants: list[Variant]) -> dict[str, str]:
    """Variant name -> fill key; every variant in exactly one group (``SetupError`` otherwise)."""
    keys = {v.name: key for key, members in groups.items() for v in members}
    count = sum(len(members) for members in groups.values())
    if count != len(keys) or set(keys) != {v.name for v in variants}:
        raise SetupError("the fill groups do not hold each variant of the sweep exactly once")
    return keys

