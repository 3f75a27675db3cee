"""Labels back to the user: LAS/LAZ with every input point, Parquet tables, PNG views.

* :func:`export_las` streams the run's input files in order (1 M records at a time) and
  writes each record again with all its original dimensions, plus extra-bytes dimensions
  ``class_id`` (uint8), ``instance_id`` (uint32), ``segment_id`` (uint64), ``score``
  (float32) and ``primitive_id`` (uint8) read from the store's label arrays, and the LAS
  ``classification`` set by :data:`LAS_CLASSIFICATION`. The output is LAS 1.4 with a
  point format of 6 or above (formats 0-5 are upgraded: their 5-bit classification
  cannot hold the element codes). The input's extra dimensions keep their stored values,
  scales, offsets and descriptions; its own VLRs, its GPS time type and (as
  ``input_classification``) its classification are kept; a classification lookup VLR
  names the codes. Records of PLY/E57 inputs with non-finite coordinates
  were dropped at ingest and are not exported (the ingest reported their count).
  Beside the file, with the same stem, it writes the class styles: ``<stem>.qml`` (a
  QGIS point cloud style) and ``<stem>.cc-classes.xml`` (a CloudCompare colour scale)
  that colour and name the codes of :data:`LAS_LEGEND`.
* :func:`export_parquet` copies the segment and tree tables.
* :func:`export_png` draws a top and a side view of a sample of the labelled points,
  coloured by class, like the paper's result figures.

All of them write each file to a temporary name and rename it at the end, so an
interrupted export never leaves a half file under the requested name.
"""

from __future__ import annotations

import os
import shutil
import uuid
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import laspy
import numpy as np
from laspy.vlrs.known import ClassificationLookupVlr

from hollowtree.classes import CLASS_NAMES, NUM_CLASSES, ClassId
from hollowtree.errors import ConfigError, PipelineError
from hollowtree.pipeline.labels import require_labels, tile_parts
from hollowtree.tiling.readers import las_crs, read_blocks
from hollowtree.tiling.store import RunStore

__all__ = ["INPUT_CLASSIFICATION", "LAS_CLASSIFICATION", "LAS_LEGEND", "CLASS_COLOURS", "cloudcompare_scale",
           "export_las", "export_parquet", "export_png", "qgis_style", "style_paths", "write_outputs"]

#: LAS classification written for each hollowtree class: the ASPRS code where the class is
#: one (1 unclassified, 2 ground); every building part has a code of its own in the
#: user-definable range 64-255 (arch 64, dome 65, minaret 66, pillar 67, wall 68, roof 69),
#: so ASPRS 6 (building) is not used. ``other`` (clutter) is 1 like unclassified.
LAS_CLASSIFICATION: dict[ClassId, int] = {
    ClassId.UNCLASSIFIED: 1, ClassId.GROUND: 2, ClassId.WALL: 68, ClassId.ROOF: 69,
    ClassId.ARCH: 64, ClassId.DOME: 65, ClassId.MINARET: 66, ClassId.PILLAR: 67, ClassId.OTHER: 1,
}
#: RGB (0-1) of each class in the PNG views, indexed by class id.
CLASS_COLOURS = np.array([
    (0.75, 0.75, 0.75), (0.55, 0.45, 0.30), (0.85, 0.70, 0.50), (0.60, 0.20, 0.20), (0.10, 0.45, 0.85),
    (0.95, 0.55, 0.05), (0.15, 0.65, 0.25), (0.60, 0.25, 0.75), (0.35, 0.35, 0.35),
])
assert len(CLASS_COLOURS) == NUM_CLASSES


def _legend() -> tuple[tuple[int, str, tuple[int, int, int]], ...]:
    named: dict[int, ClassId] = {}
    for c in sorted(LAS_CLASSIFICATION):  # a shared code is named by its lowest class id
        named.setdefault(LAS_CLASSIFICATION[c], c)
    return tuple((code, CLASS_NAMES[c], tuple(int(round(255 * v)) for v in CLASS_COLOURS[c]))
                 for code, c in sorted(named.items()))


#: ``(LAS code, name, (r, g, b) 0-255)`` of every code written, by code: the names of the
#: classification lookup VLR and the categories of the QGIS and CloudCompare styles.
LAS_LEGEND: tuple[tuple[int, str, tuple[int, int, int]], ...] = _legend()
_EXTRA = (("class_id", np.uint8, "class"), ("instance_id", np.uint32, "instance"),
          ("segment_id", np.uint64, "segment"), ("score", np.float32, "score"),
          ("primitive_id", np.uint8, "primitive"))
_UPGRADE = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}
#: Degrees per unit of the scan angle of point formats 6+ (formats 0-5: whole degrees).
SCAN_ANGLE_STEP = 0.006
#: The extra dimension that keeps a LAS input's own classification (``classification``
#: holds the labels).
INPUT_CLASSIFICATION = "input_classification"
_CHUNK = 1_000_000


def _tmp(path: Path) -> Path:
    return path.with_name(f".{path.name}.partial")


def _out_header(sources: list[dict[str, Any]]) -> laspy.LasHeader:
    first = next((s for s in sources if s.get("format") in ("las", "laz", "copc")), None)
    if first is not None:
        with laspy.open(first["path"]) as r:
            src = r.header
        pf = _UPGRADE.get(src.point_format.id, src.point_format.id)
        header = laspy.LasHeader(point_format=pf, version="1.4")
        header.scales, header.offsets = src.scales, src.offsets
        header.global_encoding.gps_time_type = src.global_encoding.gps_time_type
        for dim in src.point_format.extra_dimensions:  # raw type, scale, offset and description
            header.add_extra_dim(laspy.ExtraBytesParams(
                name=dim.name, type=dim.dtype if dim.num_elements == 1 else f"{dim.num_elements}{dim.dtype.base}",
                description=dim.description or "", scales=dim.scales, offsets=dim.offsets))
        # the user's own records, not those this writer makes (CRS, extra bytes, class names)
        header.vlrs.extend(v for v in src.vlrs if not _remade(v))
        header.evlrs = [v for v in (src.evlrs or []) if not _remade(v)] or None
        crs = las_crs(src, first["path"], writing="the labelled copy")
        if crs is not None:
            header.add_crs(crs)
        if "classification" in src.point_format.dimension_names and \
                INPUT_CLASSIFICATION not in src.point_format.dimension_names:
            header.add_extra_dim(laspy.ExtraBytesParams(
                name=INPUT_CLASSIFICATION, type=np.uint8, description="classification of the input"))
    else:
        header = laspy.LasHeader(point_format=7, version="1.4")
        header.scales = np.array([0.001, 0.001, 0.001])
        header.offsets = np.array([s for s in (sources[0].get("mins") or (0.0, 0.0, 0.0))])
    taken = set(header.point_format.dimension_names)
    for name, dt, _ in _EXTRA:
        if name in taken:
            raise ConfigError(f"input {sources[0]['path']} already has a dimension {name!r}; cannot export labels")
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=dt))
    lookup = ClassificationLookupVlr()  # names the codes for viewers that read LAS 1.4's lookup
    for code, name, _ in LAS_LEGEND:
        lookup.lookups[code] = name
    header.vlrs.append(lookup)
    return header


def _remade(vlr: Any) -> bool:
    """A VLR the exported file gets anew (the CRS, the extra-bytes description, the
    classification lookup, LAZ's own) or must not carry: COPC's info and hierarchy
    describe the input's octree layout, which the exported file does not have."""
    uid, rid = getattr(vlr, "user_id", ""), getattr(vlr, "record_id", -1)
    return (uid in ("LASF_Projection", "laszip encoded", "copc")
            or (uid == "LASF_Spec" and rid in (0, 4)))


def _labels(store: RunStore, index: np.ndarray) -> dict[str, np.ndarray]:
    lo, hi = int(index.min()), int(index.max()) + 1
    return {key: store.read_slice(f"labels/{key}", lo, hi)[index - lo] for _, _, key in _EXTRA}


def export_las(store: RunStore, out: str | Path, *, progress: bool = False) -> int:
    """Write every input point with its labels to ``out`` (.las or .laz); return the count."""
    from tqdm import tqdm

    require_labels(store)
    out = Path(out)
    if out.suffix.lower() not in (".las", ".laz"):
        raise ConfigError(f"--las {out}: the file name must end in .las or .laz")
    if not out.parent.is_dir():
        raise ConfigError(f"--las {out}: folder {out.parent} does not exist")
    sources = store.attrs["sources"]
    header = _out_header(sources)
    mapping = np.zeros(NUM_CLASSES, dtype=np.uint8)
    for c, code in LAS_CLASSIFICATION.items():
        mapping[int(c)] = code
    tmp = _tmp(out)
    n_out = 0
    total = sum(int(s["point_count"]) for s in sources)
    base = 0
    with laspy.open(tmp, mode="w", header=header, do_compress=out.suffix.lower() == ".laz") as writer, \
            tqdm(total=total, unit="pt", unit_scale=True, desc="export: las", disable=None if progress else True, leave=False) as bar:
        for s in sources:
            if not Path(s["path"]).is_file():
                raise PipelineError(f"input {s['path']} of store {store.url} is gone; cannot export")
            if s.get("format") in ("las", "laz", "copc"):
                with laspy.open(s["path"]) as r:
                    names = set(r.header.point_format.dimension_names)
                    extra = set(r.header.point_format.extra_dimension_names) & set(header.point_format.dimension_names)
                    start = 0
                    for chunk in r.chunk_iterator(_CHUNK):
                        rec = laspy.ScaleAwarePointRecord.zeros(len(chunk), header=header)
                        rec.x, rec.y, rec.z = chunk.x, chunk.y, chunk.z
                        for name in header.point_format.dimension_names:
                            if name in extra:  # stored values, as they are: no rescaling
                                rec.array[name] = chunk.array[name]
                            elif name in names and name not in ("X", "Y", "Z", "classification"):
                                rec[name] = chunk[name]
                        if "scan_angle_rank" in names and "scan_angle" in header.point_format.dimension_names:
                            # formats 0-5 (whole degrees) upgraded to 6+ (0.006 degree steps)
                            rec["scan_angle"] = np.round(np.asarray(chunk.scan_angle_rank, np.float64)
                                                         / SCAN_ANGLE_STEP).astype(np.int16)
                        if INPUT_CLASSIFICATION in header.point_format.dimension_names and "classification" in names:
                            rec[INPUT_CLASSIFICATION] = np.asarray(chunk.classification, dtype=np.uint8)
                        index = np.arange(base + start, base + start + len(chunk), dtype=np.int64)
                        _fill(rec, store, index, mapping)
                        writer.write_points(rec)
                        start += len(chunk)
                        n_out += len(chunk)
                        bar.update(len(chunk))
            else:
                for block in read_blocks(s["path"], chunk_size=_CHUNK):
                    rec = laspy.ScaleAwarePointRecord.zeros(len(block.xyz), header=header)
                    rec.x, rec.y, rec.z = block.xyz[:, 0], block.xyz[:, 1], block.xyz[:, 2]
                    if block.intensity is not None:
                        rec["intensity"] = block.intensity
                    if block.rgb is not None:
                        rec["red"], rec["green"], rec["blue"] = block.rgb.T
                    _fill(rec, store, block.index.astype(np.int64) + base, mapping)
                    writer.write_points(rec)
                    n_out += len(block.xyz)
                    bar.update(len(block.xyz) + block.n_dropped)
            base += int(s["point_count"])
    os.replace(tmp, out)
    _write_styles(out)
    return n_out


#: The QGIS version the style says it was written for: point cloud layers and their
#: classified renderer exist since 3.18; an older number would make QGIS run its
#: upgrades of old project files on the style.
_QGIS_STYLE_VERSION = "3.28.0"
#: The scale's UUID: the same for every export, so CloudCompare knows it when it is
#: imported again.
_CC_SCALE_UUID = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "hollowtree:las-classes")) + "}"


def style_paths(out: str | Path) -> tuple[Path, Path]:
    """The class styles :func:`export_las` writes beside ``out``: the QGIS style
    ``<stem>.qml`` and the CloudCompare colour scale ``<stem>.cc-classes.xml``."""
    out = Path(out)
    return out.with_name(f"{out.stem}.qml"), out.with_name(f"{out.stem}.cc-classes.xml")


def _write_styles(out: Path) -> None:
    qml, cc = style_paths(out)
    for path, data in ((qml, qgis_style()), (cc, cloudcompare_scale())):
        tmp = _tmp(path)
        tmp.write_bytes(data)
        os.replace(tmp, path)


def qgis_style() -> bytes:
    """A QGIS style (.qml) for the exported point cloud layer: the point cloud renderer
    ``classified`` on the attribute ``Classification``, one category per code of
    :data:`LAS_LEGEND` (its name and colour). The tags are those QGIS's
    ``QgsPointCloudClassifiedRenderer`` reads (``<renderer type="classified">``,
    ``<categories>``, ``<category value label color render>``, colours ``r,g,b,a``)."""
    root = ET.Element("qgis", {"version": _QGIS_STYLE_VERSION, "styleCategories": "Symbology"})
    renderer = ET.SubElement(root, "renderer", {
        "type": "classified", "attribute": "Classification", "pointSize": "2", "pointSizeUnit": "MM",
        "maximumScreenError": "0.3", "maximumScreenErrorUnit": "MM"})
    cats = ET.SubElement(renderer, "categories")
    for code, name, (r, g, b) in LAS_LEGEND:
        ET.SubElement(cats, "category", {"value": str(code), "label": name,
                                         "color": f"{r},{g},{b},255", "render": "true"})
    ET.SubElement(root, "blendMode").text = "0"
    ET.indent(root)
    doctype = "<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>\n"
    return doctype.encode() + ET.tostring(root, encoding="utf-8") + b"\n"


def cloudcompare_scale() -> bytes:
    """A CloudCompare colour scale (the Color Scale Editor's XML) for the LAS
    classification: absolute, from 0 to the highest code + 1, flat at each code's colour
    (+-0.45 around the code) and one label per code naming it. The tags are those of
    ``ccColorScale::saveAsXML`` / ``LoadFromXML`` (``<CloudCompare><ColorScale version="1">``,
    ``<Properties>`` name, uuid, absolute, minValue, range; ``<Data>`` with
    ``<step r g b pos>`` from pos 0 to 1 and ``<label val text>``)."""
    top = float(LAS_LEGEND[-1][0] + 1)
    steps: list[tuple[float, tuple[int, int, int]]] = [(0.0, LAS_LEGEND[0][2])]
    for code, _, rgb in LAS_LEGEND:
        steps += [((code - 0.45) / top, rgb), ((code + 0.45) / top, rgb)]
    steps.append((1.0, LAS_LEGEND[-1][2]))
    root = ET.Element("CloudCompare")
    scale = ET.SubElement(root, "ColorScale", {"version": "1"})  # CloudCompare wants it first
    props = ET.SubElement(scale, "Properties")
    for tag, text in (("name", "hollowtree classes"), ("uuid", _CC_SCALE_UUID), ("absolute", "1"),
                      ("minValue", "0"), ("range", f"{top:.12g}")):
        ET.SubElement(props, tag).text = text
    data = ET.SubElement(scale, "Data")
    for pos, (r, g, b) in steps:
        ET.SubElement(data, "step", {"r": str(r), "g": str(g), "b": str(b), "pos": f"{pos:.12g}"})
    for code, name, _ in LAS_LEGEND:
        ET.SubElement(data, "label", {"val": str(code), "text": name})
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _fill(rec: Any, store: RunStore, index: np.ndarray, mapping: np.ndarray) -> None:
    if not len(index):
        return
    lab = _labels(store, index)
    for name, dt, key in _EXTRA:
        rec[name] = lab[key].astype(dt)
    rec["classification"] = mapping[lab["class"]]


def export_parquet(store: RunStore, folder: str | Path) -> list[Path]:
    """Copy the segment table (and the tree's node table when the tree ran) to ``folder``."""
    import fsspec

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fs, root = fsspec.core.url_to_fs(store.url)
    root = root.rstrip("/")
    written = []
    for rel, name in (("coarse/segments.parquet", "segments.parquet"), ("tree/nodes.parquet", "tree.parquet")):
        if fs.exists(f"{root}/{rel}"):
            tmp = _tmp(folder / name)
            with fs.open(f"{root}/{rel}", "rb") as src, open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst)
            os.replace(tmp, folder / name)
            written.append(folder / name)
    if not written:
        raise PipelineError(f"store {store.url} has no segment table; run the coarse stage first")
    return written


def _sample(store: RunStore, n_max: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """World xyz and class of at most ``n_max`` labelled core points, spread over tiles."""
    attrs = store.attrs
    scale, offset = np.asarray(attrs["coords"]["scale"]), np.asarray(attrs["coords"]["offset"])
    tiles = [int(t) for t in attrs["ingest"]["tiles"]]
    recs = store.records("ingest")
    parts = store.records("labels_tiles")
    total = max(1, sum(int(recs[str(t)]["n_core"]) for t in tiles))
    rng = np.random.default_rng(seed)
    xyz_all, cls_all = [], []
    for t in tiles:
        d = store.read_unit(f"tiles/{t}", ["xyz", "core", "index"])
        core = np.flatnonzero(d["core"])
        k = min(len(core), int(np.ceil(n_max * len(core) / total)))
        pick = np.sort(rng.choice(core, size=k, replace=False)) if k < len(core) else core
        want = d["index"][pick]
        cls = np.zeros(len(pick), np.uint8)
        todo = np.ones(len(pick), bool)
        for group in tile_parts(parts, t):  # the part that holds each point
            if not todo.any():  # kept points are in each slice's first parts; dropped ones after
                break
            part_index = store.read_slice(f"{group}/index")
            at = np.minimum(np.searchsorted(part_index, want), max(len(part_index) - 1, 0))
            found = todo & (part_index[at] == want) if len(part_index) else np.zeros(len(want), bool)
            cls[found] = store.read_slice(f"{group}/class")[at[found]]
            todo &= ~found
        cls_all.append(cls)
        xyz_all.append(d["xyz"][pick] * scale + offset)
    if not xyz_all:
        return np.zeros((0, 3)), np.zeros(0, np.uint8)
    return np.concatenate(xyz_all), np.concatenate(cls_all)


def export_png(store: RunStore, out: str | Path, *, n_max: int = 400_000) -> Path:
    """Top and side views of the labelled points, coloured by class, with a legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    require_labels(store)
    out = Path(out)
    if not out.parent.is_dir():
        raise ConfigError(f"--png {out}: folder {out.parent} does not exist")
    xyz, cls = _sample(store, n_max)
    origin = xyz.min(axis=0) if len(xyz) else np.zeros(3)
    xyz = xyz - origin  # readable axes: metres from the scan's lower corner
    colours = CLASS_COLOURS[cls]
    span = np.ptp(xyz, axis=0) if len(xyz) else np.ones(3)
    width = 12.0
    h_top = width * max(span[1], 1e-6) / max(span[0], 1e-6)
    h_side = width * max(span[2], 1e-6) / max(span[0], 1e-6)
    fig, (top, side) = plt.subplots(2, 1, figsize=(width, min(24.0, h_top + h_side + 2.0)), dpi=110,
                                    gridspec_kw={"height_ratios": [max(h_top, 0.5), max(h_side, 0.5)]})
    order = np.argsort(xyz[:, 2])  # higher points drawn last in the top view
    top.scatter(xyz[order, 0], xyz[order, 1], c=colours[order], s=0.3, linewidths=0)
    top.set_aspect("equal")
    top.set_title(f"top view (origin E {origin[0]:.1f}, N {origin[1]:.1f})")
    top.set_ylabel("y (m)")
    order = np.argsort(-xyz[:, 1])  # nearer (smaller y) drawn last in the side view
    side.scatter(xyz[order, 0], xyz[order, 2], c=colours[order], s=0.3, linewidths=0)
    side.set_aspect("equal")
    side.set_title(f"side view, looking north (z from {origin[2]:.1f})")
    side.set_xlabel("x (m)")
    side.set_ylabel("z (m)")
    present = sorted(set(np.unique(cls).tolist()))
    fig.legend(handles=[Patch(color=CLASS_COLOURS[c], label=CLASS_NAMES[c]) for c in present],
               loc="lower center", ncol=len(present), frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    tmp = _tmp(out).with_suffix(".png")
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, out)
    return out


def write_outputs(store: RunStore, wf: Any, *, progress: bool = False) -> Iterator[str]:
    """Write the outputs a workflow asks for; yield one line per output."""
    o = wf.outputs
    if o.las:
        n = export_las(store, o.las, progress=progress)
        yield f"outputs: {o.las} ({n:,} points with class_id, instance_id, segment_id, score, primitive_id)"
        qml, cc = style_paths(o.las)
        yield f"outputs: {qml} (QGIS style), {cc} (CloudCompare colour scale)"
    if o.parquet:
        paths = export_parquet(store, o.parquet)
        yield f"outputs: {', '.join(str(p) for p in paths)}"
    if o.png:
        yield f"outputs: {export_png(store, o.png)}"
