"""``siloflow cache list | clear``: the fill cache."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import typer

from ..errors import SetupError, SiloflowError
from .app import _fail, app, out, printable

cache_app = typer.Typer(help="The fill cache: settled beds reused by runs of the same fill.")
app.add_typer(cache_app, name="cache")
CACHE_OPTION = typer.Option(None, "--cache", envvar="SILOFLOW_CACHE", help="cache folder (default ~/.cache/siloflow)")


@cache_app.command("list")
def cache_list(cache: Optional[Path] = CACHE_OPTION) -> None:
    """List the cached fills: key, age, size, the run that made each; and what else is in the
    cache's folder (not siloflow's, or changed since it wrote it), with the reason."""
    from ..fill_cache import FillCache
    store = FillCache(cache)
    entries, other = store.survey()
    for e in entries:
        size = sum(p.stat().st_size for p in e.files.values())
        age = (time.time() - e.info.get("time", time.time())) / 3600
        out.print(printable(f"{e.key[:16]}  {size / 1e6:8.2f} MB  {age:7.1f} h old  from {e.info.get('source')}"),
                  markup=False, highlight=False)
    out.print(f"{len(entries)} fill(s) in {store.fills}")
    _cache_others(store, other, "not fills (cache clear leaves them)")


def _cache_others(store, other: dict, what: str) -> None:
    if other:
        out.print(f"{len(other)} other item(s) in {store.fills}, {what}:")
        for name, why in other.items():
            out.print(printable(f"  {name}: {why}"), markup=False, highlight=False)


@cache_app.command("clear")
def cache_clear(key: Optional[str] = typer.Argument(None, help="a key (or its first characters); default: all"),
                cache: Optional[Path] = CACHE_OPTION) -> None:
    """Remove one cached fill, or all of them: only entries siloflow wrote whose files are unchanged
    since; anything else in the cache's folder is listed and left in place."""
    from ..fill_cache import FillCache
    store = FillCache(cache)
    try:
        done = store.clear(key)
    except SiloflowError as exc:
        _fail(exc)
    out.print(f"removed {len(done.removed)} fill(s) from {store.fills}")
    _cache_others(store, done.left, "left in place")
    if key is not None and not done.removed:
        _fail(SetupError(f"no fill {key!r} was removed" + (": see above" if done.left else
                                                            f": no cached fill's key starts with it")))
