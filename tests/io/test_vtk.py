"""Viewer files: complete periodic grids (.vti, .vtu with the wrap row/plane), the flow's .pvd series.

Read back by readers that share no code with the writers: meshio for .vtu, VTK's own
vtkXMLImageDataReader for .vti (test extra), and ElementTree (through ``io.vtk.read_vti``, which only
parses XML) for the .pvd series and its files."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.io import output, vtk
from vesicle_opt.mesh import discretize


def _disc_and_field(name, n):
    sc = vo.load_scene(name, [f"mesh.n={n}"])
    d = discretize(sc)
    x = d.nodes
    return d, np.sin(x[:, 0]) + 0.5 * np.cos(2 * x[:, 1]) + (x[:, 2] if d.dim == 3 else 0.0)


def test_vti_is_the_complete_periodic_image(tmp_path):
    """Every node, plus the wrap plane equal to the first one; origin and spacing of the box."""
    for name, n in (("ellipse-2d", 8), ("sphere-3d", 6)):
        d, phi = _disc_and_field(name, n)
        vtk.write_vti(tmp_path / "f.vti", d, {"phi": phi})
        fields, origin, spacing = vtk.read_vti(tmp_path / "f.vti")
        F = fields["phi"]
        G = phi.reshape(d.grid_shape)
        if d.dim == 2:
            F = F[:, :, 0]
        assert F.shape == tuple(k + 1 for k in d.grid_shape)
        assert np.array_equal(F[tuple(slice(0, k) for k in d.grid_shape)], G)  # the doubles' bytes: exact
        assert np.array_equal(F[-1], F[0]) and np.array_equal(F[:, -1], F[:, 0])
        lo = [b[0] for b in d.box]
        h = [(b[1] - b[0]) / k for b, k in zip(d.box, d.grid_shape)]
        assert np.allclose(origin[: d.dim], lo, rtol=0, atol=1e-15) and np.allclose(spacing[: d.dim], h, rtol=1e-15)
        # the node coordinates of the image are those of the discretisation
        i = (3, 2, 1)[: d.dim]
        assert np.allclose(origin[: d.dim] + spacing[: d.dim] * np.array(i),
                           d.nodes[np.ravel_multi_index(i, d.grid_shape)], rtol=0, atol=1e-14)


def test_vtu_of_a_grid_covers_the_box(tmp_path):
    """phi.vtu on a periodic grid: (n+1)^d points spanning [lo, hi], n^d cells, wrap values periodic."""
    d, phi = _disc_and_field("ellipse-2d", 8)
    output.write_vtk(tmp_path / "phi.vtu", d, phi)
    m = meshio.read(tmp_path / "phi.vtu")
    assert len(m.points) == 9 * 9 and m.cells[0].data.shape == (64, 4)
    assert np.allclose(m.points[:, :2].min(0), [-4, -4]) and np.allclose(m.points[:, :2].max(0), [4, 4])
    v = m.point_data["phi"].reshape(9, 9)
    assert np.array_equal(v[:8, :8], phi.reshape(8, 8)) and np.array_equal(v[8], v[0])


def test_grid_vtu_equals_meshios_own_file(tmp_path):
    """``vtk.write_vtu_grid`` (ISA-L level 1) against meshio's writer on the same points, cells and
    values (``vtk.grid_cells``), both read back by meshio: every array bitwise equal, 2D and 3D."""
    for name, n in (("ellipse-2d", 8), ("torus-table1-3d", 6)):
        d, phi = _disc_and_field(name, n)
        output.write_vtk(tmp_path / "ours.vtu", d, phi)
        points, cells = vtk.grid_cells(d)
        kind = vtk.VTK_CELL_TYPES[d.dim][0]
        meshio.write(str(tmp_path / "meshio.vtu"),
                     meshio.Mesh(points, [(kind, cells)], point_data={"phi": vtk.wrapped(d, phi).ravel()}))
        a, b = meshio.read(tmp_path / "ours.vtu"), meshio.read(tmp_path / "meshio.vtu")
        assert np.array_equal(a.points, b.points) and a.cells[0].type == b.cells[0].type == kind
        assert np.array_equal(a.cells[0].data, b.cells[0].data)
        assert np.array_equal(a.point_data["phi"], b.point_data["phi"])


def test_grid_vtu_opens_in_vtk_itself(tmp_path):
    """The grid's .vtu read by VTK's own vtkXMLUnstructuredGridReader (test extra): point and cell
    counts, the cell type, and phi at every point (the wrap included)."""
    vtkio = __import__("pytest").importorskip("vtkmodules.vtkIOXML")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    for name, n in (("ellipse-2d", 8), ("torus-table1-3d", 6)):
        d, phi = _disc_and_field(name, n)
        output.write_vtk(tmp_path / "phi.vtu", d, phi)
        reader = vtkio.vtkXMLUnstructuredGridReader()
        reader.SetFileName(str(tmp_path / "phi.vtu"))
        reader.Update()
        grid = reader.GetOutput()
        assert grid.GetNumberOfPoints() == (n + 1) ** d.dim and grid.GetNumberOfCells() == n ** d.dim
        assert grid.GetCellType(0) == vtk.VTK_CELL_TYPES[d.dim][1]
        values = vtk_to_numpy(grid.GetPointData().GetArray("phi"))
        assert np.array_equal(values, vtk.wrapped(d, phi).ravel())


def test_flow_writes_a_pvd_series_over_its_steps(tmp_path):
    """`flow --steps 20` with the default t_end = 1: 5 snapshots (flow.frames = 4) spread over the 20
    steps (not only t = 0), each a .vti the .pvd lists in time order; the last one is the final field."""
    rc = cli.main(["flow", "ellipse-2d", "--out", str(tmp_path), "-q", "--steps", "20",
                   "--set", "mesh.n=16", "--set", "solver.M=100", "--set", "flow.frames=4"])
    assert rc == 0
    sets = ET.parse(tmp_path / "phi.pvd").getroot().find("Collection").findall("DataSet")
    times = [float(s.get("timestep")) for s in sets]
    assert len(sets) == 5 and times == sorted(times) and times[0] == 0.0
    assert np.allclose(times, [0, 5e-3, 10e-3, 15e-3, 20e-3], rtol=1e-12)  # every 5 steps of k = 1e-3
    for s in sets:
        assert (tmp_path / s.get("file")).exists()
    last, _, _ = vtk.read_vti(tmp_path / sets[-1].get("file"))
    final = np.load(tmp_path / "phi.npz")["phi"].reshape(16, 16)
    assert np.array_equal(last["phi"][:16, :16, 0], final)
    assert len(list((tmp_path / "frames").glob("frame_*.png"))) == 5


def test_vti_opens_in_vtk_itself(tmp_path):
    """The .vti read by VTK's own XML reader (the library ParaView is built on; test extra), which
    shares nothing with ``io.vtk``: extent, origin, spacing and every value of the complete image."""
    vtkio = __import__("pytest").importorskip("vtkmodules.vtkIOXML")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    for name, n in (("ellipse-2d", 8), ("sphere-3d", 6)):
        d, phi = _disc_and_field(name, n)
        vtk.write_vti(tmp_path / "f.vti", d, {"phi": phi})
        reader = vtkio.vtkXMLImageDataReader()
        reader.SetFileName(str(tmp_path / "f.vti"))
        reader.Update()
        img = reader.GetOutput()
        dims = img.GetDimensions()
        assert dims[: d.dim] == tuple(k + 1 for k in d.grid_shape)  # the wrap row/plane included
        lo = [b[0] for b in d.box]
        h = [(b[1] - b[0]) / k for b, k in zip(d.box, d.grid_shape)]
        assert np.allclose(img.GetOrigin()[: d.dim], lo, rtol=0, atol=1e-15)
        assert np.allclose(img.GetSpacing()[: d.dim], h, rtol=1e-15)
        # VTK orders points x fastest; the discretisation's C order has the last axis fastest
        F = vtk_to_numpy(img.GetPointData().GetArray("phi")).reshape(dims[::-1]).transpose()
        if d.dim == 2:
            F = F[:, :, 0]
        G = phi.reshape(d.grid_shape)
        assert np.array_equal(F[tuple(slice(0, k) for k in d.grid_shape)], G)  # exact: the doubles' bytes
        assert np.array_equal(F[-1], F[0])  # periodic wrap


def test_read_vti_still_reads_the_ascii_files_of_earlier_versions(tmp_path):
    """A 2 x 2 x 1 ASCII ImageData (as ``write_vti`` wrote before it went binary), values x fastest."""
    (tmp_path / "old.vti").write_text(
        '<?xml version="1.0"?>\n<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian">\n'
        '<ImageData WholeExtent="0 1 0 1 0 0" Origin="-1.0 -2.0 0.0" Spacing="0.5 0.25 1.0">\n'
        '<Piece Extent="0 1 0 1 0 0"><PointData Scalars="phi">'
        '<DataArray type="Float64" Name="phi" format="ascii">0.1 -0.2 0.30000000000000004 1e-300</DataArray>'
        '</PointData><CellData/></Piece></ImageData></VTKFile>\n')
    fields, origin, spacing = vtk.read_vti(tmp_path / "old.vti")
    assert np.array_equal(fields["phi"][:, :, 0], [[0.1, 0.30000000000000004], [-0.2, 1e-300]])
    assert np.array_equal(origin, [-1, -2, 0]) and np.array_equal(spacing, [0.5, 0.25, 1])


def test_vti_of_a_large_grid_is_binary_and_exact(tmp_path):
    """Many zlib blocks (41^3 doubles: 552 KB, 17 blocks of 32 KiB), read back bitwise."""
    d = discretize(vo.load_scene("torus-table1-3d", ["mesh.n=40"]))
    phi = np.random.default_rng(1).standard_normal(d.n_nodes)
    vtk.write_vti(tmp_path / "f.vti", d, {"phi": phi})
    assert 'format="binary"' in (tmp_path / "f.vti").read_text()
    fields, _, _ = vtk.read_vti(tmp_path / "f.vti")
    assert np.array_equal(fields["phi"][:40, :40, :40], phi.reshape(40, 40, 40))
