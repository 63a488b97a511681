"""Thermal shapes under compression in 3D, with actin's twist (issue 16).

The 3D companion of ``thermal_compression.py`` (same metrics, same figure layout): the 3D
unit dendritic mesh and the 3D 8-generation outcrop, built with socbjax's defaults (Kirchhoff
rods with actin's GJ = 8e-3 pN·µm², EI = 0.071 pN·µm²), compressed straight and with frozen
3D thermal shapes (``socbjax.thermal_network``: two Gaussian bending angles per segment at
298 K, Lp = 17.3 µm, the rest Darboux vector on each segment's material frame) for several
seeds, with the same continuation settings.  A 3D thermal shape needs the material frame, so
only twisting networks take one.

Reported per run as in ``thermal_compression.py``: the force at the first step off zero, the
largest force within the first 5 % of the travel (pre-stress window), the secant stiffness
over the first 10 %, the first force maximum after that, the first surface crossing (no
contact model: the path beyond it is not physical) and the wall time.  Writes
``thermal_compression_3d.json`` and ``thermal_compression_3d.png``.

Run:  PYTHONPATH=. python benchmarks/thermal_compression_3d.py [--quick] [--out DIR]
(--quick: the unit mesh only, one seed).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import thermal_compression as planar

import socbjax as sj


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    plan = {"3D unit mesh": (sj.unit_dendritic_mesh(), 0.5, range(1) if args.quick else range(4), 0.01)}
    if not args.quick:
        plan["3D outcrop"] = (sj.dendritic_outcrop(), 1.5, range(3), 0.03)
    studies = {name: (planar.study(name, net, U, seeds, step), U) for name, (net, U, seeds, step) in plan.items()}
    _common.print_table(planar.HEADERS, planar.table(studies), title="thermal shapes under compression (3D, actin twist)")
    planar.figure(studies, args.out, "thermal_compression_3d", straight_label="straight (actin twist)")
    _common.write_json(args.out, "thermal_compression_3d", args,
                       {name: {"displacement_um": U, "rows": rows} for name, (rows, U) in studies.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
