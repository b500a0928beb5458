"""The contact sheet of generated structures, each exploded along its insertion direction."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asmteach.core.structure_corpus.generate import GeneratedStructure


def render_structures(
    structures: list[GeneratedStructure], out_png: str | Path, *, columns: int = 5, colors: int = 96
) -> Path:
    """A contact sheet: each structure with B pulled back along ``-v_a`` out of A (an exploded view, millimetres).

    A is wood-coloured, B blue, markers dark squares; the red arrow is ``v_a``
    ending where B's origin sits when assembled. Saved as a palette PNG of
    ``colors`` colours (a few hundred kB less than full colour).
    """
    import math

    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from PIL import Image

    from asmteach.core.library import part_polygons

    rows = math.ceil(len(structures) / columns)
    fig = plt.figure(figsize=(3.2 * columns, 3.3 * rows), dpi=100)
    for i, gs in enumerate(structures):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        T_out = gs.T_A_B.copy()
        T_out[:3, 3] -= (gs.insertion_depth + 0.010) * gs.v_a  # 10 mm clear of A
        va, ca = part_polygons(gs.part_a, np.eye(4), (0.85, 0.66, 0.42), gs.markers_a)
        vb, cb = part_polygons(gs.part_b, T_out, (0.45, 0.62, 0.90), gs.markers_b)
        ax.add_collection3d(Poly3DCollection(va + vb, facecolors=ca + cb, edgecolors=ca + cb, linewidths=0.2))
        tip = gs.T_A_B[:3, 3] * 1000.0
        tail = tip - gs.v_a * 30.0
        ax.quiver(*tail, *(tip - tail), color="crimson", arrow_length_ratio=0.25, linewidth=1.5)
        pts = np.vstack([np.vstack(va), np.vstack(vb)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mid, half = (lo + hi) / 2.0, (hi - lo).max() / 2.0 + 3.0
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=28, azim=-55)
        variant = next((str(gs.params[k]) for k in ("hole", "slot", "pin", "post") if k in gs.params), "")
        ax.set_title(
            f"{gs.family}: c = {gs.clearance * 1e3:.2f} mm\n{len(gs.markers_a)}+{len(gs.markers_b)} markers {variant}",
            fontsize=8,
        )
        ax.tick_params(labelsize=5)
    fig.suptitle("generated structures (B pulled out along -v_a): A wood, B blue, markers black, v_a red (mm)")
    fig.tight_layout()
    out = Path(out_png)
    tmp = out.with_suffix(".full.png")
    fig.savefig(tmp, format="png")
    plt.close(fig)
    with Image.open(tmp) as im:
        im.convert("RGB").quantize(colors=colors, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    tmp.unlink()
    return out
