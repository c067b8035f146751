#!/usr/bin/env python3
"""Writes the USD grooms that groom/src/usd.rs's tests read, with Pixar's own USD library
(the `usd-core` package on PyPI), each as text (.usda) and binary (.usdc):

- tests/data/usd_linear: an Xform translated by (1, 2, 3) over BasisCurves scaled by 2; Y up,
  1 metre per unit; two linear curves of 3 and 2 points, widths per vertex, displayColor per
  curve.
- tests/data/usd_cubic: Z up, 0.01 metres per unit; a bezier curve (a hook: refined), a bspline
  and a catmullRom curve along straight lines, widths constant, per vertex and varying,
  displayColor per vertex on all three.
- tests/data/usd_instanced: a class prim holding a linear curve, referenced by two
  instanceable Xforms translated by (5, 0, 0) and (10, 0, 0).

Usage (in a virtualenv): pip install usd-core && python3 groom/tests/usd_grooms.py
"""

import os

from pxr import Gf, Sdf, Usd, UsdGeom

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


def linear(stage):
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    groom = UsdGeom.Xform.Define(stage, "/Groom")
    groom.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    c = UsdGeom.BasisCurves.Define(stage, "/Groom/Hair")
    c.CreateTypeAttr(UsdGeom.Tokens.linear)
    c.CreateCurveVertexCountsAttr([3, 2])
    c.CreatePointsAttr([(0, 0, 0), (0, 1, 0), (0, 2, 0.5), (1, 0, 0), (1, 1, 0)])
    c.CreateWidthsAttr([0.1, 0.08, 0.06, 0.2, 0.1])
    c.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    c.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(0.5, 0.3, 0.1), (0.2, 0.4, 0.6)])
    c.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))


def cubic(stage):
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.Xform.Define(stage, "/Groom")
    hook = UsdGeom.BasisCurves.Define(stage, "/Groom/Bezier")
    hook.CreateTypeAttr(UsdGeom.Tokens.cubic)
    hook.CreateBasisAttr(UsdGeom.Tokens.bezier)
    hook.CreateCurveVertexCountsAttr([4])
    hook.CreatePointsAttr([(0, 0, 0), (0, 0, 3), (2, 0, 3), (2, 0, 0.5)])
    hook.CreateWidthsAttr([0.05])
    hook.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    hook.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set(
        [(0.1, 0.1, 0.1), (0.1, 0.1, 0.1), (0.1, 0.1, 0.1), (0.1, 0.1, 0.1)]
    )
    bspline = UsdGeom.BasisCurves.Define(stage, "/Groom/BSpline")
    bspline.CreateTypeAttr(UsdGeom.Tokens.cubic)
    bspline.CreateBasisAttr(UsdGeom.Tokens.bspline)
    bspline.CreateCurveVertexCountsAttr([5])
    bspline.CreatePointsAttr([(5, 0, 0), (5, 0, 1), (5, 0, 2), (5, 0, 3), (5, 0, 4)])
    bspline.CreateWidthsAttr([0.6, 0.3, 0.6, 0.3, 0.6])
    bspline.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    bspline.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set(
        [(0.2, 0.2, 0.2), (0.4, 0.4, 0.4), (0.6, 0.6, 0.6), (0.8, 0.8, 0.8), (1.0, 1.0, 1.0)]
    )
    catmull = UsdGeom.BasisCurves.Define(stage, "/Groom/CatmullRom")
    catmull.CreateTypeAttr(UsdGeom.Tokens.cubic)
    catmull.CreateBasisAttr(UsdGeom.Tokens.catmullRom)
    catmull.CreateCurveVertexCountsAttr([4])
    catmull.CreatePointsAttr([(10, 0, 0), (11, 0, 0), (12, 0, 0), (13, 0, 0)])
    catmull.CreateWidthsAttr([0.2, 0.4])
    catmull.SetWidthsInterpolation(UsdGeom.Tokens.varying)
    catmull.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set(
        [(0.9, 0.0, 0.0), (0.5, 0.5, 0.5), (0.3, 0.2, 0.1), (0.0, 0.0, 0.9)]
    )


def instanced(stage):
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/Proto")
    c = UsdGeom.BasisCurves.Define(stage, "/Proto/Hair")
    c.CreateTypeAttr(UsdGeom.Tokens.linear)
    c.CreateCurveVertexCountsAttr([2])
    c.CreatePointsAttr([(0, 0, 0), (0, 1, 0)])
    c.CreateWidthsAttr([0.1])
    c.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    for i, x in enumerate([5, 10]):
        instance = UsdGeom.Xform.Define(stage, f"/Instance{i}")
        instance.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
        instance.GetPrim().GetReferences().AddInternalReference("/Proto")
        instance.GetPrim().SetInstanceable(True)


for name, build in [("usd_linear", linear), ("usd_cubic", cubic), ("usd_instanced", instanced)]:
    for ext in ["usda", "usdc"]:
        stage = Usd.Stage.CreateNew(os.path.join(HERE, f"{name}.{ext}"))
        build(stage)
        stage.GetRootLayer().Save()
