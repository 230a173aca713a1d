#!/usr/bin/env python3
"""docs/layers.md's picture of the denoiser: raw and denoised side by side, with their errors.

Renders the shared Cornell box as bench/peers.py does (256x256, -ab 1, --lambertian) at its
fastest setting with --denoise, and writes docs/denoise.png: the raw composite and the layer
`denoised` (raw emission plus the denoised light layers), and the `direct` layer raw and
denoised, tone-mapped as the PNG preview is. When the peers bench has made this view's two
converged references (bench/out/peers/cornell), each panel gives its relMSE against their mean.

    python3 bench/denoise_figure.py      # a few seconds; writes docs/denoise.png
"""

import os
import sys

import common
import numpy as np

SCENE = os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf")
OPTIONS = ["-x", "256", "-y", "256", "-ab", "1", "--lambertian",
           "-aa", "0.3", "-ad", "64", "-as", "16", "--spp", "2", "--light-samples", "2", "--emission-samples", "32"]
REFERENCES = os.path.join(common.ROOT, "bench", "out", "peers", "cornell")


def channels(path):
    exr = common.ensure_module("OpenEXR")
    return {name: c.pixels for name, c in exr.File(path).channels().items()}


def composite(layers):
    """The R, G, B of an EXR (OpenEXR groups them as RGBA or RGB)."""
    return next(layers[k][..., :3].astype(np.float64) for k in ("RGBA", "RGB") if k in layers)


def tone_map(rgb):
    """Reinhard on luminance, then sRGB's gamma: a picture, not a measurement."""
    lum = 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]
    scale = np.where(lum > 0, 1.0 / (1.0 + lum), 1.0)[..., None]
    return np.clip((rgb * scale) ** (1 / 2.2), 0, 1)


def relmse(image, reference):
    return float(np.mean((image - reference) ** 2 / (reference * reference + 0.01)))


def main():
    common.require("bench/denoise_figure.py", ["numpy", "OpenEXR", "matplotlib"])
    common.build()
    out_dir = os.path.join(common.ROOT, "bench", "out", "denoise")
    os.makedirs(out_dir, exist_ok=True)
    exr = os.path.join(out_dir, "cornell-denoised.exr")
    stats, _ = common.render(SCENE, exr, OPTIONS + ["--denoise"])
    layers = channels(exr)
    reference = None
    # The peers bench's references (its SCENES["cornell"]: Mitsuba at 16384 spp).
    refs = [os.path.join(REFERENCES, f) for f in ("reference-icrender.exr", "reference-mitsuba-16384spp.exr")]
    if all(os.path.exists(r) for r in refs):
        reference = 0.5 * sum(composite(channels(r)) for r in refs)
    panels = [
        ("raw composite", composite(layers), reference),
        ("denoised (layer `denoised`)", layers["denoised"], reference),
        ("direct, raw", layers["direct"], None),
        ("direct_denoised", layers["direct_denoised"], None),
    ]
    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.6))
    for ax, (title, rgb, ref) in zip(axes, panels):
        ax.imshow(tone_map(rgb.astype(np.float64)))
        if ref is not None:
            title += f"\nrelMSE {relmse(rgb, ref):.2e}"
        ax.set_title(title, fontsize=10)
        ax.axis("off")
    fig.suptitle(f"Cornell box 256x256, -ab 1, 2 samples a pixel: render {stats['render_s']:.2f} s, "
                 f"denoiser {stats['denoise_s']:.2f} s (OIDN, --denoise-quality fast, guided by albedo and normal)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    path = os.path.join(common.ROOT, "docs", "denoise.png")
    fig.savefig(path, dpi=80)
    print(f"denoise_figure: wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
