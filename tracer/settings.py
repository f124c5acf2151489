"""One :class:`Settings`: every knob gridcost takes from the environment, resolved in one place.

``Settings.from_env()`` is the only reader of ``GRIDCOST_*`` variables. The CLI resolves it once
(environment, then its own flags: ``--models``, a Dask run's wall clock) and runs the target inside
``use(settings)``; a Dask task carries ``settings.to_dict()`` in its spec and runs inside ``use`` on
the worker. Code that asks :func:`current` outside any ``use`` (a notebook, a library call, a
test) gets the environment as it is at that moment.

The per-run record of what happened (stand-ins used, the network found down, a clock warning
given, timings taken) is a :class:`RunLog` carried the same way, so no module holds mutable state.

===========================  =====================  ==============================================
variable                     field                  meaning
===========================  =====================  ==============================================
``GRIDCOST_CACHE``           ``cache``              user cache (meshes, downloads, oracle, probe)
``GRIDCOST_NUMBA_CACHE``     ``numba_cache``        base folder of compiled kernels
``GRIDCOST_MODELS``          ``models``             first folder searched for meshes (``--models``)
``GRIDCOST_SHARED_MODELS``   ``shared_models``      ``../shared/models`` override; empty = off
``GRIDCOST_OFFLINE``         ``offline``            never download a mesh
``GRIDCOST_NO_STAND_INS``    ``stand_ins`` (False)  a missing mesh is an error, not a stand-in
``GRIDCOST_MACHINE_DIR``     ``machine_dir``        where the machine probe is kept
``GRIDCOST_MEMORY_BUDGET``   ``memory_budget``      bytes one structure may allocate (e.g. ``2G``)
``GRIDCOST_L1/L2/L3``        ``cache_sizes``        cache sizes instead of sysfs' (e.g. ``1M``)
``GRIDCOST_CLOCK``           ``clock``              ``wall`` forces wall-time timing
``GRIDCOST_PIN``             ``pin``                ``1`` pins the timing thread to one CPU
===========================  =====================  ==============================================
"""
from __future__ import annotations

import contextlib
import os
from contextvars import ContextVar
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Iterator, Mapping

from tracer.errors import GridcostError

_UNSET = "\0unset"  # GRIDCOST_SHARED_MODELS: unset (the default folder) differs from empty (off)


def parse_bytes(text: str) -> int:
    """``'2G'``, ``'512M'``, ``'1.5KiB'`` or ``'4096'`` as a byte count (ValueError otherwise)."""
    text = text.strip().upper()
    mult = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    if text.endswith("IB"):
        text = text[:-2]
    elif text.endswith("B"):
        text = text[:-1]
    if text and text[-1] in mult:
        return int(float(text[:-1]) * mult[text[-1]])
    return int(float(text))


def _flag(value: str | None) -> bool:
    return (value or "").strip().lower() not in ("", "0", "false", "no", "off")


def _path(value: str | None) -> str | None:
    return str(Path(value).expanduser()) if value else None


def _bytes(var: str, value: str | None) -> int | None:
    if not value:
        return None
    try:
        return parse_bytes(value)
    except ValueError:
        raise GridcostError(f"{var}={value!r} is not a byte count (e.g. 2G)") from None


@dataclass(frozen=True)
class Settings:
    """Every environment setting of gridcost (see the module's table); paths are strings so the
    object pickles and prints plainly."""
    cache: str | None = None
    numba_cache: str | None = None
    models: str | None = None
    shared_models: str | None = _UNSET
    offline: bool = False
    stand_ins: bool = True
    machine_dir: str | None = None
    memory_budget: int | None = None
    cache_sizes: tuple = (None, None, None)
    clock: str = ""
    pin: bool = False

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> "Settings":
        """The settings the environment (``os.environ`` by default) describes."""
        env = os.environ if environ is None else environ
        clock = env.get("GRIDCOST_CLOCK", "").strip().lower()
        if clock not in ("", "wall", "thread"):
            raise GridcostError(f"GRIDCOST_CLOCK={clock!r}: use 'wall' or 'thread' (or leave it unset)")
        shared = env.get("GRIDCOST_SHARED_MODELS")
        return cls(cache=_path(env.get("GRIDCOST_CACHE")),
                   numba_cache=_path(env.get("GRIDCOST_NUMBA_CACHE")),
                   models=_path(env.get("GRIDCOST_MODELS")),
                   shared_models=_UNSET if shared is None else (_path(shared) or ""),
                   offline=_flag(env.get("GRIDCOST_OFFLINE")),
                   stand_ins=not _flag(env.get("GRIDCOST_NO_STAND_INS")),
                   machine_dir=_path(env.get("GRIDCOST_MACHINE_DIR")),
                   memory_budget=_bytes("GRIDCOST_MEMORY_BUDGET", env.get("GRIDCOST_MEMORY_BUDGET")),
                   cache_sizes=tuple(_bytes(f"GRIDCOST_L{i}", env.get(f"GRIDCOST_L{i}")) for i in (1, 2, 3)),
                   clock=clock, pin=_flag(env.get("GRIDCOST_PIN")))

    def replace(self, **changes) -> "Settings":
        """A copy with ``changes`` (e.g. ``models=`` from ``--models``)."""
        if "models" in changes:
            changes["models"] = _path(changes["models"])
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """Plain values (every field)."""
        return asdict(self)

    #: what a task carries to a worker: how the client finds meshes and times; the worker's own
    #: caches, memory budget and cache sizes are its host's (from its own environment)
    SHIPPED = ("models", "offline", "stand_ins", "clock")

    def for_worker(self) -> dict:
        """The fields a Dask task carries (:data:`SHIPPED`); :meth:`on_worker` applies them."""
        return {k: getattr(self, k) for k in self.SHIPPED}

    @classmethod
    def on_worker(cls, shipped: Mapping) -> "Settings":
        """The worker's own settings with the client's shipped fields."""
        return replace(cls.from_env(), **{k: v for k, v in shipped.items() if k in cls.SHIPPED})

    @property
    def shared_models_dir(self) -> str | None:
        """The ``GRIDCOST_SHARED_MODELS`` folder, ``None`` for "use the default", ``""`` for "off"."""
        return None if self.shared_models == _UNSET else self.shared_models


@dataclass
class RunLog:
    """What happened during one run that later output must mention (filled as it happens)."""
    #: scene name -> the note of the stand-in that replaced a mesh not found
    stand_ins: dict = field(default_factory=dict)
    #: stand-ins already announced on stderr
    announced: set = field(default_factory=set)
    #: the first connection error (the network is not tried again)
    network_down: list = field(default_factory=list)
    #: the thread-clock fallback was announced
    clock_warned: bool = False
    #: timings taken (tells a file measured now from one drawn from stored points)
    timings: int = 0


_SETTINGS: ContextVar[Settings | None] = ContextVar("gridcost_settings", default=None)
_LOG: ContextVar[RunLog | None] = ContextVar("gridcost_run_log", default=None)


def current() -> Settings:
    """The settings of the run in progress, else the environment's now."""
    s = _SETTINGS.get()
    return s if s is not None else Settings.from_env()


def run_log() -> RunLog:
    """The record of the run in progress (a new one in this context when none is running)."""
    log = _LOG.get()
    if log is None:
        log = RunLog()
        _LOG.set(log)
    return log


@contextlib.contextmanager
def use(settings: Settings | None, log: RunLog | None = None) -> Iterator[Settings | None]:
    """Run the block with ``settings`` (``None``: the environment's, read when asked) and ``log``
    (a fresh :class:`RunLog` by default)."""
    t1 = _SETTINGS.set(settings)
    t2 = _LOG.set(log if log is not None else RunLog())
    try:
        yield settings
    finally:
        _LOG.reset(t2)
        _SETTINGS.reset(t1)
