"""Type stubs of the native module behind fbksd.client (checked by mypy.stubtest in the tests)."""

import os
from typing import Any, Callable, Literal, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

_Array = npt.NDArray[np.float32]
_LayoutElement = Union[str, Tuple[str, int], Tuple[str, Literal["INPUT", "OUTPUT"]]]
_TileCallback = Callable[[_Array, Tuple[int, int]], object]
_SamplesCallback = Callable[[_Array], object]

__all__ = [
    "BenchmarkClient",
    "SceneInfo",
    "FbksdError",
    "INPUT",
    "OUTPUT",
    "RenderingServer",
    "scene_digest",
    "reference_key",
    "note_reference_key",
    "scene_meta",
    "FEATURE_BUFFERS",
    "FEATURE_BUFFER_SPP",
]

INPUT: Literal["INPUT"]
OUTPUT: Literal["OUTPUT"]

class FbksdError(RuntimeError): ...

@final
class SceneInfo:
    # A plain int, float, bool or str, by key (width: int, has_dof: bool, …).
    def get(self, key: str) -> Any: ...
    def has(self, key: str) -> bool: ...
    def __contains__(self, key: str, /) -> bool: ...
    def keys(self) -> list[str]: ...

@final
class BenchmarkClient:
    def __new__(cls, argv: Sequence[str] | None = None) -> BenchmarkClient: ...
    def get_scene_info(self) -> SceneInfo: ...
    def set_sample_layout(self, layout: list[_LayoutElement], roughness: float = 0.1) -> None: ...
    def sample_size(self) -> int: ...
    def remaining_samples(self) -> int: ...
    def get_result_buffer(self) -> _Array: ...
    def evaluate_samples(self, spp: int, consumer: _TileCallback) -> None: ...
    def evaluate_sample_count(self, count: int, consumer: _SamplesCallback) -> None: ...
    def evaluate_input_samples(self, spp: int, producer: _TileCallback, consumer: _TileCallback) -> None: ...
    def evaluate_input_sample_count(self, count: int, producer: _SamplesCallback, consumer: _SamplesCallback) -> None: ...
    def send_result(self) -> None: ...

_Positions = npt.NDArray[np.float64]
# x0, y0, x1, y1, spp (pixel tiles) or first, count (free samples): int;
# keys: (n,) uint64, one per sample.
_Tile = dict[str, Union[int, npt.NDArray[np.uint64]]]
# (name, number, offset, "INPUT" | "OUTPUT") per layout element.
_Element = Tuple[str, int, int, str]

@final
class RenderingServer:
    def __new__(
        cls,
        scene_info: Callable[[], dict[str, Any]],
        fill: Callable[[_Tile, _Positions, _Array], object],
        set_layout: Callable[[list[_Element]], object] | None = None,
        tile_size: int = 32,
    ) -> RenderingServer: ...
    def run(self) -> None: ...

def scene_digest(scene_file: str | os.PathLike[str]) -> str: ...
def reference_key(generator: str, samples_per_pixel: int, scene_digest: str) -> str: ...
def note_reference_key(note: bytes) -> str: ...
def scene_meta(path: str | os.PathLike[str], renderer: str) -> dict[str, Any]: ...

FEATURE_BUFFERS: list[str]
FEATURE_BUFFER_SPP: int
