"""Shared fixtures: a tiny procedural scene that renders in milliseconds and needs no files."""

import copy

import pytest

import tress

# A ball of blond hair (light hair scatters many times, so path depth shows) under the built-in
# sky, 16x16 at 2 spp.
SCENE = {
    "camera": {"look_from": [0, 0, 4], "look_at": [0, 0, 0], "fov": 35},
    "film": {"width": 16, "height": 16, "spp": 2, "seed": 1},
    "materials": {
        "blond": {
            "Hair": {
                "Chiang": {
                    "beta_m": 0.3,
                    "beta_n": 0.3,
                    "pigment": {"Melanin": {"eumelanin": 0.3, "pheomelanin": 0.1}},
                }
            }
        },
    },
    "objects": [
        {
            "Hair": {
                "source": {"Procedural": {"style": "Ball", "strands": 300, "radius": 0.01}},
                "material": "blond",
            }
        }
    ],
    "lights": [{"Sky": {}}],
}


@pytest.fixture
def scene_dict():
    """A fresh copy of the tiny scene, free to modify."""
    return copy.deepcopy(SCENE)


@pytest.fixture(scope="session")
def scene():
    """The tiny scene, built once."""
    return tress.Scene.from_dict(SCENE)
