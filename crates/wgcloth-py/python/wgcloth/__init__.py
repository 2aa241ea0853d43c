"""wgcloth: an implicit mass-spring cloth with learned contact, on wgpu.

Scenes come from TOML files, dicts or keyword arguments; a Simulator steps
one or many worlds of them on the best adapter or the CPU path, and its
state is numpy arrays. ``gen_data`` records the contact samples a network
trains on, and ``write_weights`` hands a network trained in Python back
to the simulator.

>>> import wgcloth
>>> scene = wgcloth.Scene(model="friction", cloth={"grid": [16, 16]})
>>> sim = wgcloth.Simulator(scene, worlds=2, backend="cpu")
>>> sim.step(3)
>>> sim.positions.shape
(2, 256, 3)
"""

from wgcloth._native import (
    NEGATIVE_SLOPE,
    Scene,
    Simulator,
    WgclothError,
    gen_data,
    read_weights,
    run,
    write_usd,
    write_weights,
)

__all__ = [
    "NEGATIVE_SLOPE",
    "Scene",
    "Simulator",
    "WgclothError",
    "gen_data",
    "read_weights",
    "run",
    "write_usd",
    "write_weights",
]
