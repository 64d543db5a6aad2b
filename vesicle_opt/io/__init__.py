"""Writers: ``files`` (atomic summary.json and npz, numpy only) and ``output`` (a result's files:
phi.npz, VTK via meshio, PNG via matplotlib, loaded only when this module is)."""
