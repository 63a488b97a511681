"""Independent reference solvers, used by the tests, the demo and the benchmarks as oracles
for SOCB (they share no code with it): the planar elastica by shooting (diffrax), the
kinked cantilever, the post-buckled column, and for contact the elastica on a point obstacle, the 3D rod on a sphere
and the lobes of the clamped–clamped elastica.

Units: µm, pN, pN·µm, pN·µm².  Float64 is required (``import socbjax`` enables it).
"""

from ._column import ElasticaColumn, elastica_column_force, elastica_column_shape
from ._contact import clamped_elastica_lobe_gap, elastica_end_shortening, elastica_on_point_obstacle, rod_on_sphere
from ._elastica import (
    ElasticaProfile,
    ElasticaSolution,
    elastica_cantilever,
    elastica_kinked_cantilever,
    elastica_tip_deflection,
    shoot_elastica,
)

__all__ = [
    "ElasticaColumn",
    "ElasticaProfile",
    "ElasticaSolution",
    "clamped_elastica_lobe_gap",
    "elastica_cantilever",
    "elastica_column_force",
    "elastica_column_shape",
    "elastica_end_shortening",
    "elastica_kinked_cantilever",
    "elastica_on_point_obstacle",
    "elastica_tip_deflection",
    "rod_on_sphere",
    "shoot_elastica",
]
