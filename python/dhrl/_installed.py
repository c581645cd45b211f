"""What the extension takes from the installed packages, found relative to them, never to the
checkout that built it: ``libmujoco.so.3.17.0`` from the ``mujoco`` wheel (loaded here, before
``dhrl._dhrl``, so the extension's dependency on it resolves to that file; the extension's
``$ORIGIN/../mujoco`` run path finds the same file in a plain site-packages layout) and the
task XMLs from the ``gymnasium`` package (``envs/mujoco/assets``)."""

from __future__ import annotations

import ctypes
import importlib.metadata
import importlib.util
import pathlib

MUJOCO_VERSION = "3.17.0"
"""The MuJoCo release dhrl's physics is built against and checked on."""


def _package_folder(name: str) -> pathlib.Path | None:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        return None
    return pathlib.Path(next(iter(spec.submodule_search_locations)))


def load_libmujoco() -> pathlib.Path:
    """Loads the installed mujoco wheel's ``libmujoco.so.3.17.0`` and returns its path; an
    ``ImportError`` saying what to install when it is missing or of another version."""
    fix = f"install it with `pip install mujoco=={MUJOCO_VERSION}`"
    try:
        version = importlib.metadata.version("mujoco")
    except importlib.metadata.PackageNotFoundError:
        raise ImportError(f"dhrl needs the mujoco package, version {MUJOCO_VERSION}; {fix}") from None
    if version != MUJOCO_VERSION:
        raise ImportError(f"dhrl needs mujoco {MUJOCO_VERSION}, found mujoco {version}; {fix}")
    folder = _package_folder("mujoco")
    library = folder / f"libmujoco.so.{MUJOCO_VERSION}" if folder else None
    if library is None or not library.is_file():
        raise ImportError(f"the installed mujoco {version} has no libmujoco.so.{MUJOCO_VERSION} (at {library}); {fix}")
    try:
        ctypes.CDLL(str(library))
    except OSError as e:
        raise ImportError(f"dhrl could not load {library}: {e}; {fix}") from e
    return library


def task_assets() -> pathlib.Path:
    """The installed Gymnasium's folder of MuJoCo task XMLs."""
    folder = _package_folder("gymnasium")
    assets = folder / "envs" / "mujoco" / "assets" if folder else None
    if assets is None or not (assets / "half_cheetah.xml").is_file():
        raise ImportError(f"dhrl reads its task XMLs from Gymnasium, and found none (at {assets}); install it with `pip install gymnasium>=1.1`")
    return assets
