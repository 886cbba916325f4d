"""Deformable blocks (3DEC's "Deformable Block Motion"): the self-contained numerical core.

- :mod:`.mesh` zones a convex block into tets (:func:`tetrahedralise` -> :class:`TetMesh`);
- :mod:`.zones` constant-strain tet kernels (geometry, strain rate, forces, mass, rotation);
- :mod:`.nmd` nodal mixed discretization on strain and on stress;
- :mod:`.constitutive` zone models by name (:data:`ZONE_MODELS`: elastic, mohr_coulomb);
- :mod:`.motion` the explicit cycle and the zone critical timestep;
- :mod:`.body` :class:`DeformableBody`, one block stepped without contacts.

See ``docs/deformable.md``; the scene wiring is in :mod:`.store`, :mod:`.contact` and
:mod:`.subcontacts`.
"""

from .body import DeformableBody
from .constitutive import SHEAR_NOW, SHEAR_PAST, TENSION_NOW, TENSION_PAST, ZONE_MODELS, material
from .mesh import TetMesh, min_dihedral_angles, signed_volumes, tetrahedralise
from .motion import critical_timestep, cycle, nodal_stiffness, scaled_masses

__all__ = ["SHEAR_NOW", "SHEAR_PAST", "TENSION_NOW", "TENSION_PAST", "ZONE_MODELS",
           "DeformableBody", "TetMesh", "critical_timestep", "cycle", "material",
           "min_dihedral_angles", "nodal_stiffness", "scaled_masses", "signed_volumes",
           "tetrahedralise"]
