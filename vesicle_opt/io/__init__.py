"""Writers: summary.json, phi.npz, VTK (meshio) and PNG (matplotlib); atomic npz files."""
