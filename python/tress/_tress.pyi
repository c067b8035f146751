"""Type stubs of the extension module (its docstrings hold the details)."""

from os import PathLike
from typing import Any, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str
INTEGRATORS: list[str]
HAIR_MODELS: list[str]

_Path = Union[str, PathLike[str]]
_Floats = npt.ArrayLike

class Scene:
    @staticmethod
    def from_dict(
        scene: dict[str, Any],
        base_dir: Optional[_Path] = None,
        table_cache: Optional[_Path] = None,
    ) -> Scene: ...
    @staticmethod
    def from_ron(
        text: str, base_dir: Optional[_Path] = None, table_cache: Optional[_Path] = None
    ) -> Scene: ...
    def to_ron(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def spp(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def integrator(self) -> str: ...
    @property
    def summary(self) -> str: ...
    def render(
        self,
        spp: Optional[int] = None,
        seed: Optional[int] = None,
        integrator: Optional[str] = None,
        threads: Optional[int] = None,
        crop: Optional[Sequence[int]] = None,
        width: Optional[int] = None,
        height: Optional[int] = None,
    ) -> npt.NDArray[np.float32]: ...

def load_scene(path: _Path, table_cache: Optional[_Path] = None) -> Scene: ...

class HairModel:
    def __init__(self, model: str, table_cache: Optional[_Path] = None) -> None: ...
    @property
    def lobes(self) -> list[str]: ...
    def eval(self, wo: _Floats, wi: _Floats, h: _Floats) -> npt.NDArray[np.float32]: ...
    def pdf(self, wo: _Floats, wi: _Floats, h: _Floats) -> Union[npt.NDArray[np.float32], float]: ...
    def sample(
        self, wo: _Floats, h: _Floats, u: _Floats
    ) -> tuple[
        npt.NDArray[np.float32], npt.NDArray[np.float32], Union[npt.NDArray[np.float32], float]
    ]: ...
    def sample_weight(
        self, wo: _Floats, h: _Floats, u: _Floats
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]: ...

def run_study(
    path: _Path,
    quick: bool = False,
    out: Optional[_Path] = None,
    threads: Optional[int] = None,
    verbose: bool = False,
    table_cache: Optional[_Path] = None,
) -> dict[str, Any]: ...
