"""The files siloflow ships, found as package resources (:mod:`importlib.resources`), never by a
path relative to the source: the same in a checkout, an editable install and an installed wheel.

- the engines' deck templates: package ``siloflow.templates`` (the repository's top-level
  ``templates/``, mapped into the package by ``[tool.setuptools.package-dir]`` in pyproject.toml);
- the example cases: package ``siloflow.decks`` (the repository's top-level ``decks/``, mapped
  the same way): the demo, the quick case and the papers' cases, listed and copied out by
  ``siloflow example``;
- the packaged fast profile: ``siloflow/fast_profile.json`` (package data of ``siloflow``).

Nothing here writes: ``benchmarks/publish_fast_profile.py`` writes the fast profile in the checkout.
"""
from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable

from .errors import SetupError
from .silos.registry import SILO_KINDS

TEMPLATES = "siloflow.templates"
DECKS = "siloflow.decks"
FAST_PROFILE = "fast_profile.json"


def template_dir(engine: str) -> Traversable:
    """The folder of an engine's deck templates (``templates/<engine>/`` in the repository)."""
    return resources.files(TEMPLATES) / engine


def template_text(engine: str, name: str) -> str:
    """The text of one template of an engine (``SetupError`` if it is not shipped)."""
    path = template_dir(engine) / name
    if not path.is_file():
        raise SetupError(f"no deck template {name!r} for engine {engine!r} in the installed siloflow "
                         f"({TEMPLATES}); reinstall siloflow")
    return path.read_text(encoding="utf-8")


def fast_profile_file() -> Traversable:
    """The packaged fast profile (``siloflow/fast_profile.json``)."""
    return resources.files("siloflow") / FAST_PROFILE


def example_names() -> list[str]:
    """The example cases siloflow ships (``decks/*.yaml`` in the repository), by name, sorted."""
    return sorted(p.name[:-len(".yaml")] for p in resources.files(DECKS).iterdir()
                  if p.name.endswith(".yaml") and p.is_file())


def example_case(name: str) -> Traversable:
    """A shipped example case by its name (``quick`` or ``quick.yaml``); ``SetupError`` naming the
    shipped ones if there is none."""
    stem = name[:-len(".yaml")] if name.endswith(".yaml") else name
    if stem not in example_names():
        raise SetupError(f"no example case {name!r}; shipped: {', '.join(example_names())}")
    return resources.files(DECKS) / f"{stem}.yaml"


def example_companions(name: str) -> list[str]:
    """The files a shipped example reads beside it (a silo from STL: its ``geometry.files``)."""
    import yaml
    data = yaml.safe_load(example_text(name))
    geometry = data.get("geometry", {}) if isinstance(data, dict) else {}
    kind = geometry.get("kind")
    reads_files = isinstance(kind, str) and kind in SILO_KINDS and SILO_KINDS[kind].reads_files
    return list(geometry.get("files", [])) if reads_files else []


def example_file(name: str) -> bytes:
    """The bytes of a file shipped beside the examples (``decks/NAME``)."""
    return (resources.files(DECKS) / name).read_bytes()


def example_text(name: str) -> str:
    """The YAML text of a shipped example case (:func:`example_case`)."""
    return example_case(name).read_text(encoding="utf-8")
