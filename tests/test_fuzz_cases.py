"""Property-based fuzzing of case files (fixed seed, a few hundred examples each): every
generated case validates or is refused with a CaseError naming fields, never a traceback;
an accepted case has only finite numbers at every depth and derives and renders a checked
deck or is refused with a SiloflowError; a refused case leaves no deck on disk; a rendered
deck holds only whitelisted commands and none of the case's free text."""
from __future__ import annotations

import copy
import json
import math
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from siloflow.case_file import case_from_dict, load_case
from siloflow.deck import FORBIDDEN_WORDS
from siloflow.engine.liggghts.deck import check_deck, render_deck_text
from siloflow.derived import check_run_length, derive
from siloflow.errors import CaseError, SiloflowError

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
