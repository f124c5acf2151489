"""The mesh registry (tracer.scenes.registry): the table against MANIFEST.tsv and the shipped files, the lookup
order (--models/$GRIDCOST_MODELS, ../shared/models, tracer/data, the user cache, download), checksum
errors, the missing-mesh error, stand-ins, downloads through pooch (file:// URLs, no network), the
``models`` target and the README's target table."""
from __future__ import annotations

import csv
import dataclasses
import gzip
import hashlib
import importlib.util
import json
import re
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tracer.settings import use

from tracer.scenes import registry
from tracer.errors import GridcostError
from tracer.scenes.registry import MESHES, Source
from tracer.scenes.scene import load_scene, manifest

REPO = Path(__file__).resolve().parents[1]
VENDORED = registry.VENDORED_DIR


@pytest.fixture
def isolated(monkeypatch, tmp_path):
    """A machine without ../shared/models and without network: $GRIDCOST_MODELS an empty folder,
    ../shared/models hidden, a fresh cache, downloads off, stand-ins on. Returns the tmp folders."""
    dirs = {k: tmp_path / k for k in ("models", "shared", "cache")}
    dirs["models"].mkdir()
    monkeypatch.setenv("GRIDCOST_MODELS", str(dirs["models"]))
    monkeypatch.setenv("GRIDCOST_SHARED_MODELS", "")
    monkeypatch.setenv("GRIDCOST_CACHE", str(dirs["cache"]))
    monkeypatch.setenv("GRIDCOST_OFFLINE", "1")
    monkeypatch.delenv("GRIDCOST_NO_STAND_INS", raising=False)
    with use(None):  # a fresh run log: no stand-in announced, the network not yet found down
        yield dirs


def vendored_file(name: str) -> Path:
    return VENDORED / MESHES[name].vendored


# ---------------------------------------------------------------- the table
def test_registry_matches_manifest():
    """Every MANIFEST.tsv row is a registry mesh with the same sha256, faces, vertices and size, and
    every registry mesh is in the MANIFEST (when ../shared/models is there, as on CI)."""
    shared = registry.shared_models_dir()
    mf = shared / "MANIFEST.tsv" if shared else None
    if mf is None or not mf.is_file():
        pytest.skip("no ../shared/models/MANIFEST.tsv on this machine")
    with open(mf, newline="") as f:
        rows = {r["file"]: r for r in csv.DictReader(f, delimiter="\t")}
    assert set(rows) == {m.file for m in MESHES.values()}
    for mesh in MESHES.values():
        row = rows[mesh.file]
        assert (row["sha256"], int(row["faces"]), int(row["vertices"]), int(row["bytes"])) == \
            (mesh.sha256, mesh.faces, mesh.vertices, mesh.size), mesh.name
        assert mesh.licence and mesh.credit and mesh.sources and mesh.original, mesh.name
        assert all(re.fullmatch(r"[0-9a-f]{64}", s.sha256) for s in mesh.sources if s.sha256)


def test_every_mesh_has_urls_and_stanford_originals():
    for mesh in MESHES.values():
        assert mesh.urls and all(u.split(":")[0] in ("http", "https", "ftp") for u in mesh.urls), mesh.name
    assert registry.BUNNY_TAR in MESHES["bunny-948"].urls and registry.BUNNY_TAR in MESHES["bunny-69k"].original
    assert registry.DRAGON_TAR in MESHES["dragon-871k"].urls
    assert MESHES["dragon-48k"].sources[-1].member == "dragon_recon/dragon_vrip_res3.ply"
    assert MESHES["cornell"].sources[0].member == "CornellBox-Original.obj"


def test_vendored_files_match_the_registry():
    """Each shipped file is the published one (sha256 of its content), at most ~1 MB, ~3 MB in all, and
    listed with its licence in tracer/data/README.md; the package data config ships them."""
    import tomllib
    shipped = {m.name: vendored_file(m.name) for m in MESHES.values() if m.vendored}
    assert {"bunny-948", "bunny-3851", "bunny-16k", "dragon-11k", "cornell", "teapot", "suzanne"} <= set(shipped)
    readme = (VENDORED / "README.md").read_text()
    for name, path in shipped.items():
        assert path.is_file(), path
        assert registry.content_sha256(path) == MESHES[name].sha256, name
        assert path.stat().st_size <= 1_050_000, path
        assert f"`{MESHES[name].vendored}`" in readme and f"| {name} |" in readme, name
    assert sum(p.stat().st_size for p in shipped.values()) <= 3_000_000
    globs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["tracer"]
    packaged = {p for g in globs for p in (REPO / "tracer").glob(g) if p.is_file()}
    assert set(shipped.values()) <= packaged


# ---------------------------------------------------------------- lookup order
def test_env_dir_wins_over_vendored(isolated):
    """A file in $GRIDCOST_MODELS (models-directory layout, or the bare file name) is used before the
    shipped one; the scene says which step found it."""
    target = isolated["models"] / MESHES["bunny-948"].file
    target.parent.mkdir(parents=True)
    shutil.copyfile(vendored_file("bunny-948"), target)
    found = registry.find("bunny-948")
    assert (found.step, found.path) == ("models", target)
    scene = load_scene("bunny-948")
    assert scene.n == 948 and scene.report["lookup"] == "models" and Path(scene.source) == target
    target.unlink()
    flat = isolated["models"] / "bun_zipper_res4.ply"
    shutil.copyfile(vendored_file("bunny-948"), flat)
    assert registry.find("bunny-948").path == flat


def test_vendored_found_without_shared(isolated):
    """$GRIDCOST_MODELS empty and ../shared/models hidden: the shipped meshes load, compressed ones too."""
    for name in ("bunny-948", "dragon-11k", "cornell", "dragon-48k"):
        found = registry.find(name)
        assert found.step == "vendored", (name, found)
        scene = load_scene(name)
        assert scene.n == MESHES[name].faces and scene.report["lookup"] == "vendored"
        assert registry.stand_in_note(scene) is None
    rows = manifest()
    assert rows["bunny-948"]["found"] == "vendored" and rows["dragon-202k"]["path"] is None


def test_shared_between_env_dir_and_vendored(isolated, monkeypatch):
    shared = isolated["shared"]
    (shared / "stanford").mkdir(parents=True)
    shutil.copyfile(vendored_file("bunny-948"), shared / MESHES["bunny-948"].file)
    monkeypatch.setenv("GRIDCOST_SHARED_MODELS", str(shared))
    assert registry.find("bunny-948").step == "shared"
    assert registry.find("dragon-11k").step == "vendored"
    (isolated["models"] / "stanford").mkdir()
    shutil.copyfile(vendored_file("bunny-948"), isolated["models"] / MESHES["bunny-948"].file)
    assert registry.find("bunny-948").step == "models"


def test_checksum_mismatch_is_an_error(isolated):
    """A file found anywhere must be the published mesh: the error names both hashes and the file."""
    bad = isolated["models"] / MESHES["bunny-948"].file
    bad.parent.mkdir(parents=True)
    data = bytearray(vendored_file("bunny-948").read_bytes())
    data[-2:] = b"9\n"  # one changed index
    bad.write_bytes(bytes(data))
    import hashlib
    got = hashlib.sha256(bytes(data)).hexdigest()
    with pytest.raises(GridcostError) as info:
        load_scene("bunny-948")
    msg = str(info.value)
    assert got in msg and MESHES["bunny-948"].sha256 in msg and str(bad) in msg and "\n" not in msg


def test_missing_mesh_error_names_url_and_env_var(isolated, monkeypatch):
    monkeypatch.setenv("GRIDCOST_NO_STAND_INS", "1")
    with pytest.raises(GridcostError) as info:
        load_scene("dragon-202k")
    msg = str(info.value)
    mesh = MESHES["dragon-202k"]
    assert msg.startswith("dragon-202k:") and mesh.file in msg and "\n" not in msg
    assert mesh.sources[0].url in msg and registry.DRAGON_TAR in msg
    assert "GRIDCOST_MODELS" in msg and "GRIDCOST_NO_STAND_INS" in msg and "GRIDCOST_OFFLINE" in msg


# ---------------------------------------------------------------- stand-ins
@pytest.mark.parametrize("name", ["cow", "dragon-202k"])
def test_stand_in_is_deterministic_labelled_and_similar(isolated, monkeypatch, capfd, name):
    """A missing mesh gets a stand-in: about the same N (within 20 %; here within one face), the same
    object's shape (the base's bounds), labelled in the scene, announced once on stderr, and the same
    triangles when built again from scratch (another cache)."""
    first = load_scene(name)
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"gridcost: {name} ") and "STAND-IN" in err[0], err
    assert "GRIDCOST_NO_STAND_INS" in err[0] and MESHES[name].sources[0].url in err[0]
    real = MESHES[name].faces
    assert abs(first.n - real) <= 0.2 * real and abs(first.n - real) <= 1
    assert first.name == name and first.source.startswith("stand-in:")
    assert first.report["stand_in_for"] == name and first.report["faces_real"] == real
    note = registry.stand_in_note(first)
    assert note and name in note and "STAND-IN" in note
    base = MESHES[name].stand_in_from
    base_scene = next(load_scene(b) for b in base if MESHES[b].faces <= real and registry.find(b).found)
    np.testing.assert_allclose(first.bounds, base_scene.bounds, rtol=1e-5, atol=1e-6)
    assert load_scene(name) is not None and capfd.readouterr().err == ""  # announced once
    monkeypatch.setenv("GRIDCOST_CACHE", str(isolated["cache"].parent / "other-cache"))
    again = registry.stand_in(name)
    np.testing.assert_array_equal(again.tris, first.tris)


def test_stand_in_without_any_base_is_a_sphere(isolated, monkeypatch):
    monkeypatch.setattr(registry, "VENDORED_DIR", isolated["cache"] / "no-vendored")
    scene = load_scene("bunny-948")
    assert scene.report["stand_in_for"] == "bunny-948" and "sphere" in scene.source
    assert abs(scene.n - 948) <= 0.2 * 948


# ---------------------------------------------------------------- downloads (file:// URLs through pooch)
needs_pooch = pytest.mark.skipif(importlib.util.find_spec("pooch") is None, reason="pooch is not installed")


def _with_sources(monkeypatch, name: str, *sources: Source) -> None:
    monkeypatch.setitem(MESHES, name, dataclasses.replace(MESHES[name], sources=tuple(sources)))


@needs_pooch
def test_download_then_cache(isolated, monkeypatch, tmp_path):
    """Nothing local: the mesh is downloaded (pooch, the known sha256 checked) into the user cache, the
    next lookup finds it there; a bad or unknown-hash source is skipped for the next one."""
    monkeypatch.delenv("GRIDCOST_OFFLINE")
    monkeypatch.setattr(registry, "VENDORED_DIR", tmp_path / "no-vendored")
    good = vendored_file("bunny-948")
    wrong = vendored_file("bunny-3851")
    _with_sources(monkeypatch, "bunny-948",
                  Source(good.as_uri(), "0" * 64),        # pooch refuses: hash of the download differs
                  Source(wrong.as_uri(), None),           # downloads, but it is another mesh
                  Source(good.as_uri(), MESHES["bunny-948"].sha256))
    found = registry.find("bunny-948")
    assert found.step == "download", found
    assert found.path == isolated["cache"] / "models" / MESHES["bunny-948"].file
    assert registry.content_sha256(found.path) == MESHES["bunny-948"].sha256
    assert registry.find("bunny-948").step == "cache"
    assert load_scene("bunny-948").report["lookup"] == "cache"


@needs_pooch
@pytest.mark.parametrize("kind", ["zip", "gz"])
def test_download_archive_member_and_gzip(isolated, monkeypatch, tmp_path, kind):
    monkeypatch.delenv("GRIDCOST_OFFLINE")
    monkeypatch.setattr(registry, "VENDORED_DIR", tmp_path / "no-vendored")
    raw = vendored_file("bunny-948").read_bytes()
    if kind == "zip":
        archive = tmp_path / "bunny.zip"
        with zipfile.ZipFile(archive, "w") as z:
            z.writestr("README", "not the mesh")
            z.writestr("bunny/reconstruction/bun_zipper_res4.ply", raw)
        source = Source(archive.as_uri(), None, "bunny/reconstruction/bun_zipper_res4.ply")
    else:
        archive = tmp_path / "bun_zipper_res4.ply.gz"
        archive.write_bytes(gzip.compress(raw))
        source = Source(archive.as_uri(), hashlib.sha256(archive.read_bytes()).hexdigest())
    _with_sources(monkeypatch, "bunny-948", source)
    found = registry.find("bunny-948")
    assert found.step == "download" and found.path.read_bytes() == raw


@needs_pooch
def test_failed_download_falls_back_to_stand_in(isolated, monkeypatch, tmp_path, capfd):
    """A fetcher that cannot connect (monkeypatched): the stand-in is used, the stderr line says why,
    and the network is not tried again in this process."""
    import requests
    monkeypatch.delenv("GRIDCOST_OFFLINE")
    calls = []

    def no_network(source, mesh, workdir):
        calls.append(source.url)
        raise requests.exceptions.ConnectionError("no route to host")

    monkeypatch.setattr(registry, "fetch_source", no_network)
    scene = load_scene("dragon-202k")
    assert scene.report["stand_in_for"] == "dragon-202k"
    assert "no connection" in capfd.readouterr().err
    assert len(calls) == 1  # the first connection error stops the other sources
    registry.find("cow")
    assert len(calls) == 1


# ---------------------------------------------------------------- the models target, the README
def test_models_target_json(run_cli, tmp_path):
    env = {"GRIDCOST_MODELS": str(tmp_path / "empty"), "GRIDCOST_SHARED_MODELS": "", "GRIDCOST_OFFLINE": "1"}
    (tmp_path / "empty").mkdir()
    proc = run_cli("models", "--json", "--out", str(tmp_path / "out"), env=env)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stdout
    rep = json.loads(lines[0])
    scenes = {s["name"]: s for s in rep["scenes"]}
    assert list(scenes) == list(MESHES)
    assert [d["step"] for d in rep["lookup"]] == list(registry.STEPS)
    assert scenes["bunny-948"]["found"] and scenes["bunny-948"]["step"] == "vendored" and scenes["bunny-948"]["ok"]
    assert scenes["bunny-948"]["faces"] == 948 and "Stanford" in scenes["bunny-948"]["licence"]
    missing = scenes["dragon-871k"]
    assert not missing["found"] and "GRIDCOST_MODELS" in missing["how_to_get"]
    assert MESHES["dragon-871k"].sources[0].url in missing["how_to_get"]
    assert "dragon-48k" in missing["stand_in"]
    assert (tmp_path / "out" / "models" / "summary.md").is_file()
    text = run_cli("models", "--out", str(tmp_path / "out"), env=env)
    assert text.returncode == 0 and "dragon-871k" in text.stdout and "MISSING" in text.stdout


def readme_targets() -> set[str]:
    text = (REPO / "README.md").read_text()
    section = text.split("### Targets", 1)[1]
    names = set()
    for line in section.splitlines()[1:]:
        if line.startswith("#"):
            break
        if not line.startswith("| `"):
            continue
        first = line.split("|")[1]
        names |= {chunk.split()[0] for chunk in re.findall(r"`([^`]+)`", first)}
    return names


def test_readme_target_table_lists_every_target():
    from experiments.run import TARGETS
    assert readme_targets() - {"all"} == set(TARGETS)


def test_registry_has_no_import_side_effects():
    """Importing the registry reads no file and needs neither pooch nor platformdirs."""
    code = ("import sys; sys.modules['pooch'] = None; sys.modules['platformdirs'] = None\n"
            "import tracer.scenes.registry as r; print(r.cache_root())")
    import subprocess
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(REPO), check=False)
    assert out.returncode == 0, out.stderr
