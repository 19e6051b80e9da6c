"""glsynth view's damage bank for the seeds a page opens: the bank is named by the seed, so
each seed would add a folder to the shared cache; the server keeps a page's seeds in a folder
of its own instead, one bank at a time, removed when it stops."""

import json
import os
import tempfile
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from viewhelpers import ViewServer

    running = ViewServer(tmp_path_factory.mktemp("views"), "--quality", "preview")
    try:
        yield running
    finally:
        assert running.stop() == 130
        own = Path(tempfile.gettempdir()) / f"glsynth-view-bank-{running.proc.pid}"
        assert not own.exists()


@pytest.fixture(scope="module")
def page(server):
    from websockets.sync.client import connect

    with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
        yield ws


def _open_seed(page, seed: int) -> dict:
    from viewhelpers import receive

    page.send(json.dumps({"type": "scene", "seed": seed, "env": 0, "quality": "preview",
                          "config_toml": None}))
    while (scene := receive(page, "scene", timeout=300))["seed"] != seed:
        pass
    return scene


def test_a_seed_a_page_opens_keeps_one_damage_bank_outside_the_shared_cache(server, page):
    """The damage bank is named by the seed: a page's seeds go to the server's own folder,
    emptied at each opening and removed when it stops, never to the shared cache."""
    own = Path(tempfile.gettempdir()) / f"glsynth-view-bank-{server.proc.pid}"
    banks = []
    for seed in (1, 2):
        _open_seed(page, seed)
        banks += [p.name for p in own.glob("damage-*")]
        assert len(banks) == seed and any((own / banks[-1]).iterdir())  # one bank at a time
    shared = {p.name for p in Path(os.environ["GLSYNTH_CACHE"]).glob("damage-*")}
    assert banks[0] != banks[1] and not shared & set(banks)
