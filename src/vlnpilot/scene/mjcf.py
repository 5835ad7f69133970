"""Scene -> MJCF: the XML text and the asset dictionary (procedural PNG textures) MuJoCo loads it from."""

from __future__ import annotations

import math
from xml.sax.saxutils import quoteattr

from vlnpilot.scene.detail import DEFAULT_DETAIL, DETAIL_GROUP, is_detail, with_detail
from vlnpilot.scene.model import Scene, Solid
from vlnpilot.scene.textures import png_bytes

# Collision bits: static world geoms live in bit 0 and never test against each other (same static body);
# the drone (bit 1) collides with the world. Visual-only solids have contype=conaffinity=0.
WORLD_CONTYPE, WORLD_CONAFFINITY = 1, 2


def _f(values) -> str:
    return " ".join(f"{v:.5g}" for v in values)


def _geom(solid: Solid) -> str:
    attrs = {
        "name": solid.name,
        "type": solid.shape,
        "pos": _f(solid.pos),
        "size": _f(v for v in solid.size if solid.shape != "cylinder" or v) if solid.shape != "sphere"
        else _f(solid.size[:1]),
        "material": solid.material,
        "contype": str(WORLD_CONTYPE if solid.collide else 0),
        "conaffinity": str(WORLD_CONAFFINITY if solid.collide else 0),
        "group": "0" if solid.collide else str(DETAIL_GROUP) if is_detail(solid.name) else "1",
    }
    if solid.shape == "cylinder":
        attrs["size"] = _f(solid.size[:2])
    euler = solid.euler_deg or (0.0, 0.0, solid.yaw_deg)
    if solid.shape == "plane":  # visual skins: oriented by their in-plane axes (normal = x cross y)
        attrs["size"] = _f((solid.size[0], solid.size[1], 0.5))
        attrs["xyaxes"] = _f(solid.xyaxes)
        euler = (0.0, 0.0, 0.0)
    if euler != (0.0, 0.0, 0.0):
        attrs["euler"] = _f(math.radians(a) for a in euler)
    return "<geom " + " ".join(f"{k}={quoteattr(v)}" for k, v in attrs.items()) + "/>"


def scene_to_mjcf(scene: Scene, *, bodies: str = "", assets_xml: str = "", max_render: tuple[int, int] = (960, 720),
                  shadows: bool = False, detail: str = DEFAULT_DETAIL,
                  asset_files: dict[str, bytes] | None = None) -> tuple[str, dict[str, bytes]]:
    """MJCF for the scene. `bodies` is extra worldbody XML (the drone, a scenario's bodies), `asset_files` the
    files its `assets_xml` names (a sign's texture); returns (xml, assets). `detail` (scene/detail.py): `plain` is
    the scene as built, `rich` adds visual-only parts."""
    scene = with_detail(scene, detail)
    textures = sorted({m.texture for m in scene.materials if m.texture})
    assets = {f"{t}.png": png_bytes(t) for t in textures} | (asset_files or {})
    tex_xml = "\n    ".join(f'<texture name="{t}" type="2d" file="{t}.png"/>' for t in textures)
    mat_xml = []
    for m in scene.materials:
        a = (f'name="{m.name}" rgba="{_f(m.rgba)}" specular="{m.specular:g}" shininess="{m.shininess:g}" '
             f'emission="{m.emission:g}" reflectance="{m.reflectance:g}"')
        if m.texture:
            a += f' texture="{m.texture}" texrepeat="{_f(m.texrepeat)}" texuniform="{str(m.texuniform).lower()}"'
        mat_xml.append(f"<material {a}/>")
    lights = []
    for li in scene.lights:
        kind = 'type="directional"' if li.directional else ""
        lights.append(
            f'<light name="{li.name}" pos="{_f(li.pos)}" dir="{_f(li.direction)}" diffuse="{_f(li.diffuse)}" '
            f'attenuation="{_f(li.attenuation)}" castshadow="{str(shadows).lower()}" specular="0.1 0.1 0.1" {kind}/>'
        )
    (xmin, ymin), (xmax, ymax) = scene.bounds
    geoms = "\n    ".join(_geom(s) for s in scene.solids)
    w, h = max_render
    ambient = _f((scene.headlight,) * 3)
    xml = f"""<mujoco model="{scene.name}">
  <compiler angle="radian"/>
  <option gravity="0 0 0" timestep="0.01"/>
  <statistic center="{(xmin + xmax) / 2:.3f} {(ymin + ymax) / 2:.3f} 1.2" extent="{max(xmax - xmin, ymax - ymin):.3f}"/>
  <visual>
    <global offwidth="{w}" offheight="{h}"/>
    <quality shadowsize="{4096 if shadows else 0}" offsamples="0" numslices="16" numstacks="8" numquads="2"/>
    <map znear="0.002" zfar="3"/>
    <headlight ambient="{ambient}" diffuse="0.35 0.35 0.35" specular="0.05 0.05 0.05"/>
    <rgba haze="0.15 0.25 0.35 1"/>
  </visual>
  <asset>
    {tex_xml}
    {chr(10).join('    ' + x for x in mat_xml).strip()}
    {assets_xml}
  </asset>
  <worldbody>
    {chr(10).join('    ' + x for x in lights).strip()}
    {geoms}
    {bodies}
  </worldbody>
</mujoco>
"""
    return xml, assets
