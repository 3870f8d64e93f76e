"""Property-based fuzzing of case files (fixed seed, a few hundred examples each): every
generated case validates or is refused with a CaseError naming fields, never a traceback;
a refused case leaves no deck on disk; a rendered deck holds only whitelisted commands and
none of the case's free text."""
from __future__ import annotations

import copy
import math
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from siloflow.case import case_from_dict, load_case
from siloflow.deck import FORBIDDEN_WORDS, check_deck, render
from siloflow.errors import CaseError, SiloflowError

from conftest import QUICK

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
    try:
        case = case_from_dict(data)
    except CaseError as exc:
        assert_refusal_is_clean(exc)
        return
    # accepted: every number that can reach a deck is finite
    for key, value in case.model_dump().items():
        assert not (isinstance(value, float) and not math.isfinite(value)), key


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
