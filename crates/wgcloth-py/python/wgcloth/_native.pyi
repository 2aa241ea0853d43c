"""Type stubs of wgcloth's native module (src/*.rs)."""

import os
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

NEGATIVE_SLOPE: float
"""The LeakyReLU slope of `wgcloth train`'s networks, write_weights' default."""

Backend = Literal["auto", "gpu", "cpu"]

class WgclothError(Exception):
    """A bad configuration, file or argument, a scene the device cannot hold, a device fault."""

class Scene:
    """The thesis scene by default, or a TOML file's or a dict's (dotted keys
    allowed), with keyword arguments set over it as the file lays them out."""

    def __init__(
        self, source: str | os.PathLike[str] | dict[str, Any] | None = None, /, **overrides: Any
    ) -> None: ...
    def replace(self, values: dict[str, Any] | None = None, /, **overrides: Any) -> Scene:
        """This scene with values set over it."""
    @property
    def config(self) -> dict[str, Any]:
        """The whole configuration, laid out as its TOML file is."""
    def to_toml(self) -> str:
        """The configuration as a TOML document (`wgcloth run --config`)."""
    @property
    def vertices(self) -> int:
        """Cloth vertices."""
    @property
    def triangles(self) -> npt.NDArray[np.uint32]:
        """The cloth's triangles, shape (triangles, 3)."""

class Simulator:
    """Worlds of a scene stepped together, on the best adapter or the CPU path."""

    def __init__(
        self, scene: Scene | Sequence[Scene], worlds: int | None = None, backend: Backend = "auto"
    ) -> None: ...
    def step(self, n: int = 1) -> None:
        """Steps every world n times."""
    @property
    def positions(self) -> npt.NDArray[np.float32]:
        """Cloth positions, m, shape (worlds, vertices, 3)."""
    @property
    def velocities(self) -> npt.NDArray[np.float32]:
        """Cloth velocities, m/s, shape (worlds, vertices, 3)."""
    def report(self) -> dict[str, Any]:
        """The run so far, as `wgcloth run --worlds --report` writes it."""
    @property
    def worlds(self) -> int: ...
    @property
    def vertices(self) -> int: ...
    @property
    def steps(self) -> int: ...
    @property
    def backend(self) -> Literal["gpu", "cpu"]: ...
    @property
    def adapter(self) -> str: ...
    @property
    def notices(self) -> list[str]:
        """The notices printed when the backend was chosen."""

def run(
    scene: Scene | Sequence[Scene],
    steps: int | None = None,
    worlds: int | None = None,
    backend: Backend = "auto",
) -> dict[str, Any]:
    """What `wgcloth run` does; its report as a dict."""

def gen_data(
    model: Literal["friction", "naive"] = "friction",
    recorded: int = 200_000,
    uniform: int = 800_000,
    resting: int = 0,
    seed: int = 1,
) -> dict[str, Any]:
    """`inputs`, `targets`, `input_names`, `target_names` and `model`, as `wgcloth gen-data` writes them."""

def read_weights(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A wgcloth-mlp/1 weights file: its layers, scalers, slope and notes."""

def write_weights(
    path: str | os.PathLike[str],
    model: Literal["friction", "naive", "friction-contact"],
    layers: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]],
    input_min: npt.ArrayLike,
    input_max: npt.ArrayLike,
    output_mean: npt.ArrayLike,
    output_std: npt.ArrayLike,
    negative_slope: float = ...,
    notes: dict[str, str] | None = None,
    force: bool = False,
) -> None:
    """Writes a network trained anywhere as the file a scene's contact.weights names."""

def write_usd(
    path: str | os.PathLike[str],
    scene: Scene,
    positions: npt.ArrayLike,
    steps: Sequence[int],
    force: bool = False,
) -> None:
    """The cloth at each step (positions: frames × vertices × 3) and the body
    placed at its time, as one USD file (`wgcloth run --export usd`'s)."""
