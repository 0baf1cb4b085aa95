"""Run by pvpython (ParaView's Python) from test_paraview.py: open a file as File > Open does.

    pvpython pv_probe.py DATA OUT.json OUT.png ARRAY [READER]

Opens DATA with ``OpenDataFile`` (ParaView's default reader for the extension: Xdmf3ReaderS
for .xdmf, the PVD reader for .pvd) or with READER (e.g. ``XDMFReader``, the legacy one),
and writes OUT.json: the reader's class, its time steps, the point-array names, and the
values of ARRAY (one component per entry) at the last time step with the points (x, y) they
belong to. Then renders the last step coloured by ARRAY to OUT.png. Needs a display: run it
under ``xvfb-run -a``.
"""
import json
import sys

from paraview import servermanager
from paraview import simple
from vtk.util.numpy_support import vtk_to_numpy


def main(data, out_json, out_png, array, reader_name=None):
    if reader_name:
        reader = getattr(simple, reader_name)(FileNames=[data])
    else:
        reader = simple.OpenDataFile(data)
    if reader is None:
        raise SystemExit(f"ParaView found no reader for {data}")
    times = list(reader.TimestepValues) if reader.TimestepValues else []
    last = times[-1] if times else 0.0
    reader.UpdatePipeline(last)
    obj = servermanager.Fetch(reader)
    # composite outputs (a multiblock) hold the one grid as their first leaf
    while obj.IsA("vtkCompositeDataSet"):
        it = obj.NewIterator()
        it.InitTraversal()
        obj = it.GetCurrentDataObject()
    pd = obj.GetPointData()
    names = [pd.GetArrayName(i) for i in range(pd.GetNumberOfArrays())]
    values = vtk_to_numpy(pd.GetArray(array)).tolist() if array in names else None
    points = vtk_to_numpy(obj.GetPoints().GetData())[:, :2].tolist()
    with open(out_json, "w") as fh:
        json.dump({"reader": reader.GetXMLName(), "times": times, "arrays": names,
                   "values": values, "points": points}, fh)
    view = simple.GetActiveViewOrCreate("RenderView")
    view.ViewSize = [900, 560]
    view.ViewTime = last
    display = simple.Show(reader, view)
    display.SetRepresentationType("Points")
    display.PointSize = 3
    simple.ColorBy(display, ("POINTS", array))
    display.RescaleTransferFunctionToDataRange(True, False)
    display.SetScalarBarVisibility(view, True)
    simple.ResetCamera(view)
    view.CameraParallelProjection = 1
    simple.SaveScreenshot(out_png, view, ImageResolution=[900, 560])


if __name__ == "__main__":
    main(*sys.argv[1:])
