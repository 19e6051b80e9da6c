"""`glsynth export` checks its --out path before any work (validate before doing work)."""

import pytest

from glsynth.cli import main


def test_a_non_glb_path_is_refused_before_the_environment_is_built(tmp_path, capsys,
                                                                    monkeypatch):
    import glsynth.world.environment as environment

    def built(*args, **kwargs):
        pytest.fail("export built the environment before refusing its --out path")

    monkeypatch.setattr(environment, "build_environment", built)
    out = tmp_path / "x.txt"
    assert main(["export", "--seed", "0", "--env", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "glTF binary" in err and ".glb" in err and "Traceback" not in err, err
    assert not out.exists() and not (tmp_path / "scene.json").exists()
