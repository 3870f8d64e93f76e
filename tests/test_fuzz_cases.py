"""Property-based fuzzing of case files (fixed seed, a few hundred examples each): every
generated case validates or is refused with a CaseError naming fields, never a traceback;
an accepted case has only finite numbers at every depth and derives and renders a checked
deck or is refused with a SiloflowError; a refused case leaves no deck on disk; a rendered
deck holds only whitelisted commands and none of the case's free text."""
from __future__ import annotations

import copy
import functools
import json
import math
import re
import weakref
from collections import OrderedDict

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import siloflow.derived
import siloflow.geometry
from siloflow.case import Case
from siloflow.case_file import case_from_dict, load_case
from siloflow.case_reader import locate_inserts
from siloflow.deck import FORBIDDEN_WORDS
from siloflow.design_loads import bulk_solid, design_loads
from siloflow.engine.liggghts.deck import check_deck, render_deck_text
from siloflow.derived import check_run_length, derive
from siloflow.errors import CaseError, SiloflowError
from siloflow.geometry.container import Container

from conftest import QUICK, ROOT, render
from test_case_loading import memory_cap

BASE = yaml.safe_load(QUICK.read_text())
FUZZ = settings(max_examples=300, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

HOSTILE = ["shell rm -rf /", "include /etc/passwd", "variable x python os.system", "../../etc", "/abs/path",
           "a\nshell touch /tmp/pwned", "${x}", "$(whoami)", "`id`", "na me", "é", "\u202e", "x" * 5000, ""]
values = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(2 ** 70), max_value=2 ** 70),
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0, 1e-308, 1e308, -1e308, 5e-324]),
    st.text(max_size=50), st.sampled_from(HOSTILE), st.lists(st.integers(), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2))


def leaf_paths(data, prefix=()):
    if isinstance(data, dict):
        for k, v in data.items():
            yield from leaf_paths(v, prefix + (k,))
    elif isinstance(data, list):
        for k, v in enumerate(data):
            yield from leaf_paths(v, prefix + (k,))
    yield prefix


def mutate(data, path, action, value):
    data = copy.deepcopy(data)
    if not path:
        return value if action == "set" else data
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    if action == "set":
        parent[path[-1]] = value
    elif action == "delete" and isinstance(parent, dict):
        del parent[path[-1]]
    elif action == "add" and isinstance(parent, dict):
        parent[f"extra_{abs(hash(str(value))) % 1000}"] = value
    return data


PATHS = sorted(set(leaf_paths(BASE)), key=str)


def assert_refusal_is_clean(exc: CaseError):
    assert exc.problems, "a CaseError must list its problems"
    for where, message in exc.problems:
        assert isinstance(where, str) and where, exc.problems
        assert isinstance(message, str) and message
        assert "Traceback" not in message


@FUZZ
@given(mutations=st.lists(st.tuples(st.sampled_from(PATHS), st.sampled_from(["set", "delete", "add"]), values),
                          min_size=1, max_size=3))
def test_mutated_cases_validate_or_are_refused_by_field(mutations):
    data = BASE
    for path, action, value in mutations:
        try:
            data = mutate(data, path, action, value)
        except (KeyError, IndexError, TypeError):
            continue   # an earlier mutation removed or replaced the parent
    assert_refused_or_sound(data)


def numbers_in(data, where="case"):
    """(path, number) of every int and float in a nested dump of dicts, lists and tuples."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield from numbers_in(v, f"{where}.{k}")
    elif isinstance(data, (list, tuple)):
        for k, v in enumerate(data):
            yield from numbers_in(v, f"{where}[{k}]")
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        yield where, data


def assert_derives_and_renders(case):
    """``case`` derives and renders a deck that passes the deck check, or a SiloflowError says why
    not; any other exception fails the test."""
    try:
        with memory_cap(2 * 2 ** 30):         # a runaway mesh fails the test instead of the machine
            plan, deck = _derive_and_render(case)
    except SiloflowError as exc:
        assert str(exc).strip()
        return
    check_deck(deck)
    assert not FORBIDDEN_WORDS.search(deck)


def assert_refused_or_sound(data) -> None:
    """A case dict is refused cleanly, or accepted with every number (at any depth) finite, and
    then derives and renders a checked deck or is refused with a SiloflowError."""
    try:
        case = case_from_dict(data)
    except CaseError as exc:
        assert_refusal_is_clean(exc)
        return
    for where, value in numbers_in(case.model_dump()):
        assert math.isfinite(value), where
    assert_derives_and_renders(case)


def _derive_and_render(case):
    """(plan, deck text) of a case, checking the run plan on the way (its walls included)."""
    plan = derive(case)
    assert all(isinstance(w, str) and w for w in plan.warnings)
    assert check_run_length(plan, allow_long=True) == plan.total_planned_steps
    # the plan's own values (its JSON writes a non-finite number as null, which would hide it)
    for where, value in numbers_in(plan.model_dump(), "plan"):
        assert math.isfinite(value), where
    for where, value in numbers_in(json.loads(plan.to_json()), "plan.json"):
        assert math.isfinite(value), where
    return plan, render_deck_text(plan)


SCALED_BASES = {name: yaml.safe_load((ROOT / name).read_text()) for name in [
    "decks/quick.yaml", "decks/demo.yaml", "decks/paper_b_quick.yaml", "tests/data/small_silo.yaml", "tests/data/poly_silo.yaml",
    "tests/data/shrink_silo.yaml", "tests/data/slab_silo.yaml", "tests/data/slab_dust.yaml",
    "tests/data/clump_silo.yaml"]}
FACTORS = [0.0, 1e-9, 1e-6, 1e-3, 0.1, 0.5, 0.9, 0.99, 1.01, 1.1, 2.0, 10.0, 1e3, 1e6, 1e9, -1.0]


@settings(max_examples=200, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_scaled_cases_derive_and_render_or_are_refused(data):
    """Plausible cases with numbers scaled towards and past their bounds (most stay valid, unlike
    random values): each is refused with a CaseError, or derives and renders a checked deck or
    is refused with a SiloflowError."""
    name = data.draw(st.sampled_from(sorted(SCALED_BASES)))
    case_data = copy.deepcopy(SCALED_BASES[name])
    paths = numeric_paths(case_data)
    for path in data.draw(st.lists(st.sampled_from(paths), min_size=1, max_size=3, unique=True)):
        value = _get(case_data, path)
        new = value * data.draw(st.sampled_from(FACTORS))
        case_data = mutate(case_data, path, "set", round(new) if isinstance(value, int) else new)
    assert_refused_or_sound(case_data)


def _get(data, path):
    for key in path:
        data = data[key]
    return data


def numeric_paths(data) -> list:
    """Paths of the int and float leaves of a case dict."""
    return sorted((p for p in set(leaf_paths(data)) if p and isinstance(_get(data, p), (int, float))
                   and not isinstance(_get(data, p), bool)), key=str)


@FUZZ
@given(name=st.one_of(st.sampled_from(HOSTILE), st.text(max_size=80)), description=st.sampled_from(HOSTILE))
def test_hostile_strings_never_reach_a_deck(tmp_path_factory, name, description):
    data = dict(copy.deepcopy(BASE), name=name, description=description)
    folder = tmp_path_factory.mktemp("fuzz") / "deck"
    try:
        case = case_from_dict(data)
    except CaseError as exc:
        assert_refusal_is_clean(exc)
        assert any(w.startswith("name") or w == "description" for w, _ in exc.problems)
        return
    try:
        render(case, folder)
    except SiloflowError:
        assert not folder.exists()             # nothing half-written
        return
    deck = (folder / "in.liggghts").read_text()
    check_deck(deck)
    assert not FORBIDDEN_WORDS.search(deck)
    if description.strip():
        assert description not in deck


@FUZZ
@given(text=st.one_of(st.text(max_size=300), st.binary(max_size=300).map(lambda b: b.decode("latin-1"))))
def test_arbitrary_yaml_text_validates_or_is_refused(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("yaml") / "case.yaml"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        load_case(path)
    except CaseError as exc:
        assert_refusal_is_clean(exc)


@pytest.mark.parametrize("text,words", [
    ("a: &x [1, 2]\nb: *x\n", "aliases"),
    ("".join(f"l{k}: &l{k} [" + ",".join([f"*l{k - 1}"] * 9 if k else ["x"] * 9) + "]\n" for k in range(9)), "aliases"),
    ("name: a\nname: b\n", "duplicate key"),
    ("!!python/object/apply:os.system ['id']\n", "could not determine a constructor"),
])
def test_yaml_bombs_tags_and_duplicates_are_refused(tmp_path, text, words):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CaseError, match=words):
        load_case(path)


def test_huge_file_is_refused_before_parsing(tmp_path):
    path = tmp_path / "huge.yaml"
    path.write_text("description: '" + "x" * 1_200_000 + "'\n")
    with pytest.raises(CaseError, match="larger than"):
        load_case(path)


# ------------------------------------------------------------------ every number of every example at its extremes
#: the example cases siloflow ships
EXAMPLES = sorted((ROOT / "decks").glob("*.yaml"))
#: a design section with every numeric design field (the examples have none), so that the EN 1991-4
#: loads of a cylinder example are computed at the extremes too
DESIGN = {"material": "wheat", "unit_weight": 8000.0, "K": 0.5, "mu": 0.4, "phi_r_deg": 34.0, "C_op": 0.5,
          "action_assessment_class": 2, "eccentricity": 0.0}
SCHEMA = Case.model_json_schema()
#: the smallest positive float (subnormal) and nearly the largest
TINY, HUGE = 5e-324, 1.7e308


def _resolve(node: dict) -> dict:
    while "$ref" in node:
        node = SCHEMA["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return node


def _branch(node: dict, value) -> dict:
    """The schema of ``value`` in ``node``: a union's member by its ``kind``, else by the value's type."""
    node = _resolve(node)
    options = [_resolve(o) for o in node.get("anyOf", node.get("oneOf", []))]
    if not options:
        return node
    if isinstance(value, dict) and "kind" in value:
        for o in options:
            if o.get("properties", {}).get("kind", {}).get("const") == value["kind"]:
                return o
    wanted = {dict: ("object",), list: ("array",), int: ("integer", "number"), float: ("number",)}[type(value)]
    return next(o for o in options if o.get("type") in wanted)


def number_schema(data: dict, path: tuple) -> dict:
    """The JSON schema (bounds, type) of the number at ``path`` in the case dict ``data``."""
    node, value = SCHEMA, data
    for key in path:
        node = _branch(node, value)
        if isinstance(key, int):
            node = node["prefixItems"][key] if "prefixItems" in node else node["items"]
        else:
            node = node.get("properties", {}).get(key) or node["additionalProperties"]
        value = value[key]
    return _branch(node, value)


def numbers_at(data, path=()):
    """(path, number) of every int and float of a case dict."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield from numbers_at(v, path + (k,))
    elif isinstance(data, list):
        for k, v in enumerate(data):
            yield from numbers_at(v, path + (k,))
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        yield path, data


def extremes(node: dict) -> list:
    """The values a number of schema ``node`` is tried at: 0, -1, tiny, huge and hugely negative,
    and at each bound the numbers just inside and just outside it (the bound itself is one)."""
    integer = node.get("type") == "integer"
    values = {0, -1, 2 ** 63, -2 ** 63} if integer else {0.0, -1.0, TINY, HUGE, -HUGE}
    for key, inward in (("minimum", 1), ("exclusiveMinimum", 1), ("maximum", -1), ("exclusiveMaximum", -1)):
        if key in node:
            b = node[key]
            step = (lambda d: int(b) + d) if integer else (lambda d: float(np.nextafter(b, d * np.inf)))
            inside, outside = (b, step(-inward)) if key in ("minimum", "maximum") else (step(inward), b)
            values |= {int(inside) if integer else float(inside), int(outside) if integer else float(outside)}
    return sorted(values)


def field_path(path: tuple) -> str:
    """A path as siloflow's errors write it: ``sensors.heights[0]``."""
    return "".join(f"[{k}]" if isinstance(k, int) else ("." if i else "") + k for i, k in enumerate(path))


def names_field(problems, field: str) -> bool:
    """Whether a refusal names ``field`` (``a.b.c``): a problem at it or inside it; or one whose message
    names its path or a part of it below the top section (``a.b``: the outlet whose polygon it is);
    or one at its section, a sibling or an ancestor whose message names it (``c``)."""
    bare = re.sub(r"\[\d+\]", "", field)
    section, _, leaf = bare.rpartition(".")
    parts = bare.split(".")
    named = [".".join(parts[:k]) for k in range(2, len(parts) + 1)] or [bare]
    for where, message in problems:
        where = re.sub(r"\[\d+\]", "", where)
        if where == bare or where.startswith(bare + ".") or any(re.search(rf"\b{re.escape(n)}\b", message)
                                                                for n in named):
            return True
        near = where == section or where.rpartition(".")[0] == section or section.startswith(where + ".")
        if section and near and re.search(rf"\b{leaf}\b", message):
            return True
    return False


class Remembered:
    """A pure function with its last ``size`` results remembered by ``key(*args, **kwargs)`` (which
    may hold objects compared by identity: the answer is reused only for those same objects); a
    list of meshes of more than 100k triangles is not kept (memory)."""

    def __init__(self, function, key, size: int):
        self.function, self.key, self.size, self.store = function, key, size, OrderedDict()

    def __call__(self, *args, **kwargs):
        key, same = self.key(*args, **kwargs)
        hit = self.store.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], same)):
            self.store.move_to_end(key)
            return hit[1]
        result = self.function(*args, **kwargs)
        if not isinstance(result, list) or sum(len(m.triangles) for m in result) <= 100_000:
            self.store[key] = (same, result)
            while len(self.store) > self.size:
                self.store.popitem(last=False)
        return result


@pytest.fixture
def remembered(monkeypatch):
    """derive with its pure, costly steps remembered (the same answers, computed once): the walls'
    meshes of a silo, a mesh silo's files read and its volume below a height, a clump's volume.
    Without them the few hundred plans of each example take minutes (a mesh silo's bed height alone
    0.3 s, a wheat grain's volume 0.07 s)."""
    from siloflow.clumps import ClumpShape, union_volume
    from siloflow.geometry import read_container, silo_meshes
    clump_volume = functools.lru_cache(maxsize=64)(union_volume)
    monkeypatch.setattr(ClumpShape, "volume", property(lambda clump: clump_volume(clump.centers, clump.radii)))
    monkeypatch.setattr(siloflow.geometry, "read_container", Remembered(
        read_container, lambda files, scale, outline, origin: ((tuple(map(str, files)), scale, outline,
                                                                 tuple(origin)), ()), 4))

    def walls_key(silo, bounds, sectors, z, radius, sensors=True, container=None):
        return (silo.model_dump_json(), tuple(bounds), sectors, z, radius, sensors, id(container)), (container,)
    monkeypatch.setattr(siloflow.geometry, "silo_meshes", Remembered(silo_meshes, walls_key, 8))
    volumes = {}
    volume_below = Container.volume_below

    def remembered_volume_below(self, h):
        ref, known = volumes.get(id(self), (None, None))
        if ref is None or ref() is not self:
            known = {}
            volumes[id(self)] = (weakref.ref(self), known)
        if h not in known:
            known[h] = volume_below(self, h)
        return known[h]
    monkeypatch.setattr(Container, "volume_below", remembered_volume_below)


#: the numbers that set how many triangles the walls have: at their upper bounds (a 1000 m wall of
#: 3 cm facets is 5e6 triangles, 11-25 s to build and check; 1024 sides 4-6 s) the case is planned
#: with the example's own walls in place of its own; walls of such sizes are test_mesh_quality's
#: (cyl-tall, cyl-segments-1024)
WALL_SIZES = ("geometry.height", "geometry.mesh_segments")


def extreme_outcome(example, data: dict, field: str, walls=None) -> str | None:
    """None when the case ``data`` (``example`` with one number changed, at ``field``) is refused
    by a CaseError naming the field, or plans with finite numbers only (and its EN 1991-4 loads
    are finite or refused); else what went wrong. ``walls``: the walls' meshes to plan with
    instead of making them (see WALL_SIZES)."""
    try:
        case = locate_inserts(case_from_dict(data), example.parent)
        if walls is None:
            plan = derive(case)
        else:
            real, siloflow.derived.wall_meshes = siloflow.derived.wall_meshes, lambda *args, **kwargs: walls
            try:
                plan = derive(case)
            finally:
                siloflow.derived.wall_meshes = real
    except CaseError as exc:
        return None if names_field(exc.problems, field) else f"refused without naming it: {exc.problems}"
    except Exception as exc:                          # noqa: BLE001 - any other exception is the finding
        return f"{type(exc).__name__}: {exc}"
    bad = [where for where, value in numbers_in(plan.model_dump(), "plan") if not math.isfinite(value)]
    if bad:
        return f"non-finite numbers in the plan: {bad[:5]}"
    if plan.geometry.kind not in ("cylinder", "hopper"):
        return None
    s = case.design
    for top in ("flat", "heap"):
        try:
            solid = bulk_solid(s.material, unit_weight=s.unit_weight, K=s.K, mu=s.mu, phi_r=s.phi_r_deg, C_op=s.C_op)
            loads = design_loads(plan.geometry, solid, plan.fill.bed_height_estimate, s.wall_type,
                                 s.action_assessment_class, s.eccentricity, top=top)
        except ValueError:                            # siloflow design's refusal (a message, exit 1)
            continue
        except Exception as exc:                      # noqa: BLE001
            return f"design loads ({top} top): {type(exc).__name__}: {exc}"
        wall = (loads.z >= loads.transition) & (loads.z < loads.surface - loads.h_o)
        for name in ("p_hf", "p_wf", "p_vf", "p_he", "p_we", "p_pf", "p_pe", "n_zSk"):
            if not np.isfinite(np.asarray(getattr(loads, name))[wall]).all():
                return f"design loads ({top} top): non-finite {name}"
    return None


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.stem)
def test_every_number_of_every_example_at_its_extremes(example, remembered):
    """Issue 55.8 (an OverflowError, a ZeroDivisionError and NaN loads from schema-valid numbers):
    every number of each example case (the case as validated: its defaults too, and a design
    section), one at a time, at 0, -1, tiny, huge, and on and just either side of each of its
    bounds, is refused by a CaseError naming that field, or plans with finite numbers only (its
    EN 1991-4 loads finite or refused): never another exception."""
    data = yaml.safe_load(example.read_text())
    data["design"] = DESIGN
    full = case_from_dict(data).model_dump(mode="json", by_alias=True, exclude_none=True)
    assert extreme_outcome(example, full, "name") is None          # the example itself plans
    own_walls = derive(locate_inserts(case_from_dict(full), example.parent)).meshes
    failures, tried = [], 0
    for path, _ in numbers_at(full):
        node, field = number_schema(full, path), field_path(path)
        for extreme in extremes(node):
            tried += 1
            walls = own_walls if field in WALL_SIZES and extreme == node.get("maximum") else None
            problem = extreme_outcome(example, mutate(full, path, "set", extreme), field, walls)
            if problem:
                failures.append(f"{field} = {extreme!r}: {problem}")
    assert tried > 100
    assert not failures, f"{len(failures)} of {tried}:\n" + "\n".join(failures)
