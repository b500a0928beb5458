"""Generated two-part structures, as a user's CAD would hand them to us: millimetre STL files and a structure YAML.

Issue 23: the ten hand-made structures of ``configs/parts/set1`` and ``set2``
are what the pipeline was tuned on; these families are not. Each family is a
function ``(rng) -> GeneratedStructure`` and every size, the clearance, the
hole kind and the marker layout are drawn from the seed:

====================  ==========================================================
``round_peg``         round peg with a head, in a blind or through hole
``square_peg``        square peg with a head, in a blind or through hole
``hex_peg``           hexagonal peg with a head, in a blind or through hole (a plate when A is thin)
``d_peg``             D-section peg (a flat) with a head
``keyed_peg``         round peg with a key along its side, in a keyed hole
``dovetail_slide``    dovetail slider pushed along a dovetail groove (v_a horizontal)
``t_slot_slide``      T slider pushed along a T-slot (v_a horizontal)
``side_pin``          headed pin pushed sideways into a hole in a block's face (v_a horizontal); the pin is
                      modelled standing on its head, so T_A_B holds a 90 deg rotation
``cap_on_post``       a cap with a bore lowered onto a post standing on a base
``bracket_on_block``  a U bracket lowered over a block
====================  ==========================================================

Units and frames: metres inside, millimetres only in the written STL files.
Each part's frame has its origin at the centre of its bounding box's bottom
face, z up as the part is modelled in its natural rest (the convention of the
hand-made sets). ``T_A_B`` is B's frame in A's frame, assembled: B rests on
its seat (a shoulder, a groove floor, an end stop, a post top), touching A
without interpenetrating it. ``v_a`` is the unit direction, in A's frame,
along which B moves *into* that pose. ``clearance`` is B's lateral play
along each of ``play_axes`` (A's frame) in the assembled pose, 0.2-1 mm.

Markers (``DICT_4X4_50``): 1-4 per part, each flat on an outer face that is
visible when assembled (not in a hole, not on a mating face, not under the
other part), its square plus a one-cell white quiet zone (the renderer's
default) and 1 mm inside the face's edges; ids unique across the structure;
at least one marker of A and one of B face within 90 deg of each other, so
one camera sees both parts' markers (the ArUco teacher's view choice needs that).

Graspability by the Nextage's parallel gripper (85 mm stroke,
:data:`asmteach.plugins.robots.nextage.build_urdf.GRIPPER`): every part's
narrower horizontal bounding-box side (x or y, as modelled) is at most 70 mm,
15 mm under the stroke; the assembled structure is 20-120 mm across.

The package: :mod:`.markers` (where markers may go and the layout drawn),
:mod:`.build` (sections, prisms and a family's raw output), one module per
family group (:mod:`.pegs`, :mod:`.slides`, :mod:`.pin_cap_bracket`),
:mod:`.generate` (part frames, markers, the corpus, marker checks),
:mod:`.writer` (STL + YAML files and ``asmteach make-structures``) and
:mod:`.picture` (the contact sheet).
"""

from __future__ import annotations

from asmteach.core.structure_corpus.generate import (
    STRUCTURE_FAMILIES,
    GeneratedStructure,
    generate_structure,
    marker_problems,
    structure_corpus,
)
from asmteach.core.structure_corpus.markers import MARKER_DICTIONARY
from asmteach.core.structure_corpus.picture import render_structures
from asmteach.core.structure_corpus.writer import add_make_structures_command, write_run_config, write_structure

__all__ = [
    "MARKER_DICTIONARY",
    "STRUCTURE_FAMILIES",
    "GeneratedStructure",
    "add_make_structures_command",
    "generate_structure",
    "marker_problems",
    "render_structures",
    "structure_corpus",
    "write_run_config",
    "write_structure",
]
