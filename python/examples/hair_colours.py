"""Renders a ball of procedural hair in three colours side by side and prints how much light
each colour's fibers return (their albedo), with nothing but tress and NumPy.

    python examples/hair_colours.py --size 128 --spp 32 --out colours.ppm
"""

import argparse

import numpy as np

import tress

# Eumelanin concentration: blond, brown, black.
COLOURS = {"blond": 0.3, "brown": 1.3, "black": 4.0}


def scene(eumelanin, size, spp):
    return tress.Scene.from_dict(
        {
            "camera": {"look_from": [0, 0, 4], "look_at": [0, 0, 0], "fov": 35},
            "film": {"width": size, "height": size, "spp": spp, "seed": 1},
            "materials": {"hair": {"Hair": {"Chiang": {"pigment": {"Melanin": {"eumelanin": eumelanin}}}}}},
            "objects": [
                {
                    "Hair": {
                        "source": {"Procedural": {"style": "Ball", "strands": 2000, "radius": 0.008}},
                        "material": "hair",
                    }
                }
            ],
            "lights": [{"Sky": {}}],
        }
    )


def albedo(model, n=50_000, seed=1):
    """∫ f cos θ_i dω_i over incident directions, averaged over h, seen from θ_o = 0."""
    rng = np.random.default_rng(seed)
    _, f, pdf = model.sample([0, 0, 1], rng.uniform(-1, 1, n), rng.uniform(0, 1, (n, 4)))
    return (f[pdf > 0] / pdf[pdf > 0, None]).sum(axis=0) / n


def srgb(linear):
    """Linear radiance → 8-bit sRGB."""
    c = np.clip(linear, 0, 1)
    c = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return (c * 255 + 0.5).astype(np.uint8)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--integrator", default="path", help=f"one of {tress.INTEGRATORS} or RON")
    parser.add_argument("--out", default="colours.ppm", help="binary PPM of the three renders")
    args = parser.parse_args()

    images = []
    for name, eumelanin in COLOURS.items():
        image = scene(eumelanin, args.size, args.spp).render(integrator=args.integrator)
        model = tress.HairModel(f"Chiang(pigment: Melanin(eumelanin: {eumelanin}))")
        a = albedo(model)
        print(f"{name:6} mean radiance {image.mean(axis=(0, 1)).round(4)}  fiber albedo {a.round(3)}")
        images.append(image)
    strip = srgb(np.concatenate(images, axis=1))
    with open(args.out, "wb") as f:
        f.write(b"P6 %d %d 255\n" % (strip.shape[1], strip.shape[0]))
        f.write(strip.tobytes())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
