"""The report of a ``clrt bench`` run (clrt/bench/paper.py): the paper's own
figures, the rows measured here, and the files made from them.

``Report`` writes, into the run's ``--out`` folder, ``tables.md`` (the
paper's Tables 1-5 with its reduction formula (8), Mrays/s and the speed-up
over the paper's time, every measurement, and the detail-loss table),
``times.csv``, ``time-vs-faces.png`` and ``kernel-vs-faces.png`` (log-log
charts drawn with Pillow) and, with the detail-loss test, ``detail-loss.png``
and ``detail-loss.csv``.
"""

from __future__ import annotations

import csv
import io
import math
import platform
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from clrt.bench.common import rate
from clrt.config import BUILDERS, VOLUMES

# --------------------------------------------------------------------------- the paper's numbers

SHAPES = VOLUMES
PAPER_SIZE = (200, 200)   # pixels of every image the paper timed; speed-ups compare only at this size


@dataclass(frozen=True)
class PaperRow:
    """One mesh of the paper's experiments: render times in ms at 200 x 200 on an
    i5-3340 + GeForce GTX 550 Ti (CUDA 6.5).  None: not in the paper."""

    file: str
    faces: int
    basic: int | None
    cuda: int | None
    bvh: tuple          # (box, sphere, ellipse)
    bvh_cuda: tuple | None


# The paper's Tables 1-3 (basic vs CUDA), Table 4 (basic vs BVH; its pages are
# also captioned "Tabel 2") and Table 5 (BVH vs BVH + CUDA; also captioned
# "Tabel 3"), keyed by our suite name (the file name without extension).
# ddboat was not run without a BVH; Table 5 leaves out icosphere, jar, cemara,
# sword, key_b, sphere and ellipse.
PAPER: dict[str, PaperRow] = {r.file.rsplit(".", 1)[0].lower(): r for r in (
    PaperRow("triangle.obj", 1, 667, 632, (607, 798, 852), (620, 807, 837)),
    PaperRow("triangle2.obj", 2, 878, 728, (733, 915, 961), (688, 857, 835)),
    PaperRow("triangle3.obj", 3, 924, 747, (631, 721, 1266), (625, 703, 837)),
    PaperRow("triangle4.obj", 4, 1087, 818, (714, 798, 1500), (630, 735, 985)),
    PaperRow("box1.obj", 8, 1649, 916, (1242, 1713, 1511), (766, 863, 877)),
    PaperRow("diamond.obj", 33, 7014, 2655, (3586, 6302, 6119), (1142, 1820, 1618)),
    PaperRow("icosphere.obj", 80, 14247, 5203, (3803, 5517, 4913), None),
    PaperRow("bunny500.obj", 200, 42211, 14115, (7038, 21085, 8609), (1678, 5702, 1689)),
    PaperRow("bunny1500.obj", 200, 39592, 13414, (4914, 16257, 6778), (2095, 4677, 1440)),
    PaperRow("jar.obj", 204, 31073, 10501, (13582, 14040, 12851), None),
    PaperRow("cemara.obj", 246, 38929, 12933, (8906, 6913, 5414), None),
    PaperRow("sword.obj", 338, 55568, 18600, (6718, 2776, 1226), None),
    PaperRow("key_b.3ds", 588, 98024, 32114, (8329, 8419, 1875), None),
    PaperRow("gourd.obj", 648, 116987, 40977, (17404, 26882, 9985), (3639, 8066, 2986)),
    PaperRow("sphere.obj", 960, 159811, 54165, (19988, 8215, 2770), None),
    PaperRow("ellipse.obj", 960, 168727, 58074, (20967, 14455, 4748), None),
    PaperRow("knob.obj", 1344, 273141, 80490, (54315, 45134, 23271), (11592, 11504, 4793)),
    PaperRow("dolphin.obj", 1692, 285055, 93924, (35047, 38752, 9585), (7007, 13166, 2836)),
    PaperRow("apel.obj", 1704, 306869, 84352, (61153, 72912, 32501), (10493, 20220, 7118)),
    PaperRow("camel.obj", 4884, 775864, 242459, (140918, 109696, 15625), (33556, 34573, 5618)),
    PaperRow("beethoven.ply", 5030, 948919, 339572, (120614, 117617, 54105), (25526, 34385, 15816)),
    PaperRow("teapot.obj", 6320, 1254613, 397596, (240452, 371324, 51374), (52614, 115077, 18332)),
    PaperRow("bunny.off", 6966, 1203699, 383018, (296368, 223483, 26837), (63693, 71831, 8503)),
    PaperRow("sample1.3DS", 23578, 4089124, 902385, (502300, 1573880, 185232), (105226, 519273, 65486)),
    PaperRow("dragon.ply", 37986, 7158953, 901752, (1253351, 600198, 341669), (260460, 166891, 97871)),
    PaperRow("ddboat.obj", 82666, None, None, (6796711, 6665842, 6699465), (901114, 916287, 906206)),
)}

# The paper's detail-loss placements (Tables 6-8): eye and light on the +z axis.
PAPER_DETAIL = (("apel.obj", 250.0, 240.0), ("sample1.3DS", 20.0, 18.0))


def reduction(t1: float, t2: float) -> float:
    """The paper's formula (8): render-time reduction in % from time 1 to time 2."""
    return (t1 - t2) / t1 * 100.0


def paper_time(mesh: str, faces: int, program: str) -> float | None:
    """The paper's time (ms) for ``program`` on the mesh of that name, when the
    paper has one and our mesh has the paper's face count."""
    row = PAPER.get(mesh)
    if row is None or row.faces != faces:
        return None
    if program == "basic":
        return row.basic
    if program == "gpu":
        return row.cuda
    shape = program.rsplit("-", 1)[1]
    times = row.bvh_cuda if program.startswith("bvh-gpu-") else row.bvh
    return None if times is None else times[SHAPES.index(shape)]


# --------------------------------------------------------------------------- programs

@dataclass(frozen=True)
class Program:
    name: str
    kind: str        # 'CPU' or 'GPU': the device type it runs on
    accel: str       # 'none' or a bounding-volume shape


PROGRAMS = {p.name: p for p in (
    Program("basic", "CPU", "none"), Program("gpu", "GPU", "none"),
    *(Program(f"bvh-{s}", "CPU", s) for s in SHAPES),
    *(Program(f"bvh-gpu-{s}", "GPU", s) for s in SHAPES),
)}
LABELS = {"basic": "basic", "gpu": "GPU", **{f"bvh-{s}": f"BVH {s}" for s in SHAPES},
          **{f"bvh-gpu-{s}": f"BVH+GPU {s}" for s in SHAPES}}


@dataclass
class Run:
    """One timed (mesh, program, builder): milliseconds unless named otherwise."""

    mesh: str
    faces: int
    source: str
    program: str
    builder: str                 # '-' without a BVH
    kind: str
    device: str
    width: int
    height: int
    warmup: int
    repeat: int
    load_ms: float
    init_ms: float
    build_ms: float
    upload_ms: float
    cold_setup_ms: float
    raygen_ms: float
    colour_ms: float
    kernel_ms: float
    readback_ms: float
    frame_wall_ms: float
    total_ms: float
    mrays_wall: float
    mrays_kernel: float
    paper_ms: float | None = None
    speedup: float | None = None

    @property
    def variant(self) -> str:
        return self.program if self.builder == "-" else f"{self.program}/{self.builder}"


CSV_COLUMNS = list(Run.__dataclass_fields__)


def variants(programs: list[str], builders: list[str]) -> list[tuple[str, str]]:
    """(program, builder) pairs in run order; a program without a BVH once, with builder "-"."""
    return [(p, "-") if PROGRAMS[p].accel == "none" else (p, b)
            for p in programs for b in (["-"] if PROGRAMS[p].accel == "none" else builders)]


@dataclass
class DetailRow:
    """One image of the detail-loss test (the paper's Tables 6-8) and how it differs."""

    mesh: str
    faces: int
    eye: tuple
    light: tuple
    placement: str                 # the paper's mesh and placement it stands for
    program: str
    builder: str
    kind: str
    device: str
    differ_from_basic: int | None    # None: basic not run
    differ_same_device: int | None   # from the no-BVH program on the same device
    max_channel_diff: int | None
    image: np.ndarray = field(repr=False, default=None)


# --------------------------------------------------------------------------- output

def _ms(v: float | None) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if v >= 100:
        return f"{v:,.0f}"
    if v >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}%"


def factor(v: float | None) -> str:
    """A speed-up: "3.1x", "2,036x"; "-" when there is none."""
    if v is None:
        return "-"
    return f"{v:,.0f}x" if v >= 100 else f"{v:.3g}x"


def _md_table(headers: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


class Report:
    """Everything measured so far, and the files made from it."""

    def __init__(self, out: Path, command: str, width: int, height: int, builders: list[str], args,
                 notes: list[str]):
        self.out, self.command, self.width, self.height = out, command, width, height
        self.builders, self.args, self.notes = builders, args, notes
        self.date = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        self.runs: list[Run] = []
        self.detail: list[DetailRow] = []

    def find(self, mesh: str, program: str, builder: str = "-") -> Run | None:
        return next((r for r in self.runs if r.mesh == mesh and r.program == program
                     and r.builder == builder), None)

    def meshes(self) -> list[tuple[str, int]]:
        seen = {}
        for r in self.runs:
            seen.setdefault(r.mesh, r.faces)
        return list(seen.items())

    # -- files

    FILES = ("times.csv", "tables.md", "time-vs-faces.png", "kernel-vs-faces.png", "detail-loss.png",
             "detail-loss.csv")

    def write(self) -> None:
        from clrt.output import write_file
        force = self.args.force

        def write(name: str, data) -> None:
            write_file(data, self.out / name, force, "--out")
        write("times.csv", self.csv())
        write("tables.md", self.markdown())
        series = self.series("total_ms")
        write("time-vs-faces.png", loglog_chart(
            series, f"Total time per frame (as the paper's times), {self.width}x{self.height}",
            "total ms (read + build + upload + frame)"))
        write("kernel-vs-faces.png", loglog_chart(
            self.series("kernel_ms"), f"Kernel time per frame (ray generation + colour), "
                                      f"{self.width}x{self.height}", "kernel ms"))
        if self.detail:
            write("detail-loss.png", detail_sheet(self.detail))
            write("detail-loss.csv", self.detail_csv())

    def csv(self) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, CSV_COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in self.runs:
            row = asdict(r)
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else ("" if v is None else v))
                        for k, v in row.items()})
        return buf.getvalue()

    def detail_csv(self) -> str:
        buf = io.StringIO()
        cols = ["mesh", "faces", "placement", "eye", "light", "program", "builder", "kind", "device",
                "differ_from_basic", "differ_same_device", "max_channel_diff"]
        w = csv.DictWriter(buf, cols, lineterminator="\n")
        w.writeheader()
        for d in self.detail:
            w.writerow({c: ("" if getattr(d, c) is None else
                            " ".join(f"{x:.6g}" for x in getattr(d, c)) if c in ("eye", "light")
                            else getattr(d, c)) for c in cols})
        return buf.getvalue()

    def series(self, metric: str) -> list[tuple[str, str, str, list]]:
        """(label, colour, style, points) per program and builder: the colour
        tells the program, the line style and marker (``STYLES``) the builder."""
        out = []
        for program, builder in variants(list(PROGRAMS), BUILDERS):
            pts = [(r.faces, getattr(r, metric)) for r in self.runs
                   if r.program == program and r.builder == builder]
            if pts:
                label = LABELS[program] + ("" if builder == "-" else f" ({builder})")
                out.append((label, COLOURS[program], STYLES[builder], sorted(pts)))
        return out

    # -- Markdown

    def markdown(self) -> str:
        a = self.args
        devices = {}
        for r in self.runs:
            devices.setdefault(r.kind, r.device)
        lines = [
            "# The paper's experiments on this machine",
            "",
            f"- date: {self.date}",
            f"- command: `{self.command}`",
            f"- host: {platform.system()} {platform.machine()}, Python {platform.python_version()}",
            *(f"- {kind} programs: {devices.get(kind, 'not run')}" for kind in ("CPU", "GPU")),
            f"- {self.width}x{self.height} pixels, one ray per pixel, one point light: ambient + diffuse + "
            f"specular + shadow, no reflection (the paper's shading); default framing of each mesh",
            f"- BVH builders: {', '.join(self.builders)}; leaf size {a.leaf_size}",
            f"- timing: {a.warmup} warm-up frame(s) on a cold renderer, then a second renderer timed "
            f"stage by stage and the median of {a.repeat} frame(s)",
            "",
            "**total** = reading the mesh file + flattening + BVH build + upload + one frame (median), "
            "which is what the paper's times include; **kernel** = ray generation + pixel colour from "
            "OpenCL profiling events; **frame** = host wall clock around one `Renderer.render` "
            "(kernels, sRGB encode, read back). Reduction % is the paper's formula (8), "
            "(t1 - t2) / t1 x 100. **speed-up** = the paper's time / our total for the same mesh "
            "and program (only where the paper has the mesh at the same face count, and only at the "
            "paper's 200x200 pixels). The paper ran "
            "on an i5-3340 and a GeForce GTX 550 Ti; its basic/BVH programs were single-threaded "
            "C++, ours run the same OpenCL kernels on the CPU device.",
        ]
        if self.notes:
            lines += ["", "Notes:", *(f"- {n}" for n in self.notes)]
        lines += ["", self._table1(), "", *self._table2(), "", *self._table3(), "", self._all(), ""]
        lines += self._detail_md()
        return "\n".join(lines) + "\n"

    def _table1(self) -> str:
        rows = []
        for mesh, faces in self.meshes():
            b, g = self.find(mesh, "basic"), self.find(mesh, "gpu")
            if not (b and g):
                continue
            row = PAPER.get(mesh) if paper_time(mesh, faces, "basic") else None
            rows.append([mesh, f"{faces:,}", _ms(b.total_ms), _ms(g.total_ms), _pct(reduction(b.total_ms, g.total_ms)),
                         _ms(row.basic) if row else "-", _ms(row.cuda) if row else "-",
                         _pct(reduction(row.basic, row.cuda)) if row else "-", factor(b.speedup), factor(g.speedup)])
        head = "## Tables 1-3 of the paper: basic vs GPU (no BVH), total ms"
        if not rows:
            return head + "\n\nNot run: needs both the basic and the gpu program."
        return head + "\n\n" + _md_table(
            ["mesh", "faces", "basic", "GPU", "reduction", "paper basic", "paper CUDA", "paper reduction",
             "speed-up basic", "speed-up GPU"], rows)

    def _table2(self) -> list[str]:
        out = []
        for builder in self.builders:
            rows = []
            for mesh, faces in self.meshes():
                b = self.find(mesh, "basic")
                first = True
                for k, shape in enumerate(SHAPES):
                    r = self.find(mesh, f"bvh-{shape}", builder)
                    if not r:
                        continue
                    # basic skipped (--max-brute-faces, as the paper did for
                    # ddboat): the BVH row stays, basic and reduction blank.
                    paper_bvh = paper_time(mesh, faces, f"bvh-{shape}")
                    paper_basic = paper_time(mesh, faces, "basic")
                    rows.append([mesh if first else "", f"{faces:,}" if first else "",
                                 (_ms(b.total_ms) if b else "-") if first else "", shape,
                                 _ms(r.total_ms), _pct(reduction(b.total_ms, r.total_ms)) if b else "-",
                                 _ms(paper_bvh),
                                 _pct(reduction(paper_basic, paper_bvh)) if paper_basic and paper_bvh
                                 else "-", factor(r.speedup), rate(r.mrays_wall)])
                    first = False
            head = f"## Table 4 of the paper: basic vs BVH on the CPU device, builder {builder}, total ms"
            out += [head, "", _md_table(
                ["mesh", "faces", "basic", "BVH", "BVH ms", "reduction", "paper BVH", "paper reduction",
                 "speed-up", "Mrays/s"], rows) if rows else "Not run: needs the bvh-* programs.", ""]
        return out[:-1]

    def _table3(self) -> list[str]:
        out = []
        for builder in self.builders:
            rows = []
            for mesh, faces in self.meshes():
                first = True
                for k, shape in enumerate(SHAPES):
                    c, g = self.find(mesh, f"bvh-{shape}", builder), self.find(mesh, f"bvh-gpu-{shape}", builder)
                    if not (c and g):
                        continue
                    row = PAPER.get(mesh) if paper_time(mesh, faces, f"bvh-gpu-{shape}") else None
                    rows.append([mesh if first else "", f"{faces:,}" if first else "", shape,
                                 _ms(c.total_ms), _ms(g.total_ms), _pct(reduction(c.total_ms, g.total_ms)),
                                 _ms(row.bvh[k]) if row else "-", _ms(row.bvh_cuda[k]) if row else "-",
                                 _pct(reduction(row.bvh[k], row.bvh_cuda[k])) if row else "-",
                                 factor(g.speedup), rate(g.mrays_wall)])
                    first = False
            head = f"## Table 5 of the paper: BVH vs BVH + GPU, builder {builder}, total ms"
            out += [head, "", _md_table(
                ["mesh", "faces", "shape", "BVH", "BVH + GPU", "reduction", "paper BVH", "paper BVH+CUDA",
                 "paper reduction", "speed-up BVH+GPU", "Mrays/s"], rows)
                if rows else "Not run: needs the bvh-* and bvh-gpu-* programs.", ""]
        return out[:-1]

    def _all(self) -> str:
        rows = [[r.mesh, f"{r.faces:,}", r.program, r.builder, r.kind, _ms(r.load_ms), _ms(r.build_ms),
                 _ms(r.upload_ms), _ms(r.cold_setup_ms), _ms(r.kernel_ms), _ms(r.frame_wall_ms),
                 _ms(r.total_ms), rate(r.mrays_wall), rate(r.mrays_kernel), _ms(r.paper_ms), factor(r.speedup)]
                for r in self.runs]
        return "## All measurements (ms)\n\n" + _md_table(
            ["mesh", "faces", "program", "builder", "device", "read", "BVH build", "upload", "cold setup",
             "kernel", "frame", "total", "Mrays/s (frame)", "Mrays/s (kernel)", "paper", "speed-up"], rows)

    def _detail_md(self) -> list[str]:
        if not self.detail:
            return []
        lines = ["## Detail loss (the paper's Tables 6-8)", "",
                 "Each mesh rendered once by every program with the paper's detail-loss placement scaled "
                 "to it: the eye on the +z axis through the mesh's centre at the distance that frames it, "
                 "the light on the same axis at the paper's fraction of the eye's distance (apel.obj: "
                 "240/250; sample1.3DS: 18/20). Counts are pixels (any channel) that differ from basic's "
                 "image, and from the no-BVH image of the same device. `detail-loss.png` shows them all "
                 "side by side.", ""]
        rows = [[d.mesh, f"{d.faces:,}", d.placement.split(":")[0], d.program, d.builder, d.kind,
                 "-" if d.differ_from_basic is None else f"{d.differ_from_basic:,}",
                 "-" if d.differ_same_device is None else f"{d.differ_same_device:,}",
                 "-" if d.max_channel_diff is None else d.max_channel_diff] for d in self.detail]
        lines.append(_md_table(["mesh", "faces", "stands for", "program", "builder", "device",
                                "pixels differing from basic", "from no-BVH on same device",
                                "largest channel difference"], rows))
        same = [d for d in self.detail if d.differ_same_device]
        cross = [d for d in self.detail if d.kind == "GPU" and d.differ_from_basic]
        lines += ["", ("On each device every program draws the same image, bit for bit: the BVH changes "
                       "which triangles are tested, never the arithmetic of the test or of the shading."
                       if not same else f"**{len(same)} image(s) differ from the no-BVH image of their own "
                                         "device** (see the table): a bug.")]
        gpu_rows = [d for d in self.detail if d.kind == "GPU" and d.differ_from_basic is not None]
        if gpu_rows and not cross:
            lines += ["", "The GPU's images are identical to the CPU's as well."]
        if cross:
            lines += ["", "Between the CPU and the GPU device some pixels differ. Both run the same OpenCL "
                      "source, but OpenCL C lets each device round differently: single-precision division "
                      "and `sqrt` (in `normalize`, `length`) may be off by up to 2.5 and 3 ulp, and each "
                      "compiler decides where `a * b + c` becomes a fused multiply-add (one rounding instead "
                      "of two). The last bits of hit distances, normals and shadow-ray origins therefore "
                      "differ; a pixel changes where a colour lies on an 8-bit rounding step, where a "
                      "shadow ray grazes an edge, or where a camera ray passes within rounding of a "
                      "silhouette or a shared edge. The paper's 'exactly the same image' holds per device."]
        return lines


# --------------------------------------------------------------------------- pictures

COLOURS = {"basic": "#000000", "gpu": "#7f7f7f", "bvh-box": "#1f77b4", "bvh-sphere": "#2ca02c",
           "bvh-ellipse": "#d62728", "bvh-gpu-box": "#17becf", "bvh-gpu-sphere": "#bcbd22",
           "bvh-gpu-ellipse": "#ff7f0e"}
# Line style (and marker) per BVH builder: solid line + filled circle, dashed +
# hollow square, dotted + filled triangle.  "-": the programs without a BVH.
STYLES = {"-": "solid", "paper": "solid", "sah": "dashed", "device": "dotted"}


def _png(image) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


def _decade_label(k: int) -> str:
    return f"{10 ** k:,}" if k >= 0 else f"{10.0 ** k:.{-k}f}"


def loglog_chart(series, title: str, ylabel: str, xlabel: str = "faces",
                 size: tuple[int, int] = (1000, 640)) -> bytes:
    """PNG bytes of a log-log line chart.  ``series``: (label, colour, style,
    [(x, y), ...]) each, style "solid", "dashed" or "dotted" (or a bool: dashed); non-positive points are left out."""
    from PIL import Image, ImageDraw, ImageFont
    font = ImageFont.load_default()
    w, h = size
    img = Image.new("RGB", size, "white")
    d = ImageDraw.Draw(img)
    left, right, top, bottom = 90, w - 250, 50, h - 70
    d.text((left, 15), title, fill="black", font=font)
    pts = [(x, y) for _, _, _, s in series for x, y in s if x > 0 and y > 0 and math.isfinite(y)]
    if not pts:
        d.text((left, h // 2), "no data", fill="black", font=font)
        return _png(img)
    xs, ys = np.log10([p[0] for p in pts]), np.log10([p[1] for p in pts])
    x0, x1 = math.floor(xs.min()), math.ceil(xs.max())
    y0, y1 = math.floor(ys.min()), math.ceil(ys.max())
    x1, y1 = max(x1, x0 + 1), max(y1, y0 + 1)

    def px(x):
        return left + (math.log10(x) - x0) / (x1 - x0) * (right - left)

    def py(y):
        return bottom - (math.log10(y) - y0) / (y1 - y0) * (bottom - top)

    for k in range(x0, x1 + 1):                       # vertical grid, x ticks
        for m in range(1, 10):
            if k == x1 and m > 1:
                break
            x = px(m * 10.0 ** k)
            d.line([(x, top), (x, bottom)], fill="#dddddd" if m == 1 else "#f2f2f2")
            d.line([(x, bottom), (x, bottom + (6 if m == 1 else 3))], fill="black")
        label = _decade_label(k)
        d.text((px(10.0 ** k) - 3 * len(label), bottom + 9), label, fill="black", font=font)
    for k in range(y0, y1 + 1):                       # horizontal grid, y ticks
        for m in range(1, 10):
            if k == y1 and m > 1:
                break
            y = py(m * 10.0 ** k)
            d.line([(left, y), (right, y)], fill="#dddddd" if m == 1 else "#f2f2f2")
            d.line([(left - (6 if m == 1 else 3), y), (left, y)], fill="black")
        label = _decade_label(k)
        d.text((left - 10 - 6 * len(label), py(10.0 ** k) - 6), label, fill="black", font=font)
    d.rectangle([left, top, right, bottom], outline="black")
    d.text(((left + right) // 2 - 3 * len(xlabel), bottom + 30), xlabel + " (log)", fill="black", font=font)
    ytext = Image.new("RGB", (8 * len(ylabel) + 40, 14), "white")
    ImageDraw.Draw(ytext).text((0, 0), ylabel + " (log)", fill="black", font=font)
    ytext = ytext.rotate(90, expand=True)
    img.paste(ytext, (8, (top + bottom) // 2 - ytext.height // 2))

    for label, colour, style, s in series:
        style = _style(style)
        s = [(px(x), py(y)) for x, y in s if x > 0 and y > 0 and math.isfinite(y)]
        for a, b in zip(s, s[1:]):
            _line(d, a, b, colour, style)
        for x, y in s:
            _marker(d, x, y, colour, style)
    ly = top
    for label, colour, style, _ in series:               # legend
        style = _style(style)
        _line(d, (right + 15, ly + 6), (right + 45, ly + 6), colour, style)
        _marker(d, right + 30, ly + 6, colour, style)
        d.text((right + 52, ly), label, fill="black", font=font)
        ly += 18
    return _png(img)


def _style(style) -> str:
    """A series' line style: "solid", "dashed" or "dotted" (a bool: dashed or not)."""
    if isinstance(style, bool):
        return "dashed" if style else "solid"
    if style not in ("solid", "dashed", "dotted"):
        raise ValueError(f"unknown line style {style!r}")
    return style


def _marker(d, x, y, colour, style: str) -> None:
    if style == "dashed":
        d.rectangle([x - 3, y - 3, x + 3, y + 3], outline=colour, width=2)
    elif style == "dotted":
        d.polygon([(x, y - 4), (x - 4, y + 3), (x + 4, y + 3)], fill=colour)
    else:
        d.ellipse([x - 3, y - 3, x + 3, y + 3], fill=colour)


def _line(d, a, b, colour, style="solid") -> None:
    style = _style(style)
    if style == "solid":
        d.line([a, b], fill=colour, width=2)
        return
    dash = 7.0 if style == "dashed" else 2.0      # dotted: short dashes, short gaps
    length = math.dist(a, b)
    steps = max(1, int(length // dash))
    for i in range(0, steps, 2):
        t0, t1 = i / steps, min(1.0, (i + 1) / steps)
        d.line([(a[0] + (b[0] - a[0]) * t0, a[1] + (b[1] - a[1]) * t0),
                (a[0] + (b[0] - a[0]) * t1, a[1] + (b[1] - a[1]) * t1)], fill=colour, width=2)


def detail_sheet(rows: list[DetailRow]) -> bytes:
    """PNG bytes: one row of images per mesh, one column per program, labelled."""
    from PIL import Image, ImageDraw, ImageFont
    font = ImageFont.load_default()
    meshes = list(dict.fromkeys(r.mesh for r in rows))
    columns = max(sum(1 for r in rows if r.mesh == m) for m in meshes)
    ih, iw = rows[0].image.shape[:2]
    scale = max(1, math.ceil(128 / max(iw, ih)))             # small renders are enlarged, pixel for pixel
    tw, th = iw * scale, ih * scale
    cell_w, label_h, margin = max(tw, 130) + 10, 48, 190
    sheet = Image.new("RGB", (margin + columns * cell_w, len(meshes) * (th + label_h + 10) + 10), "white")
    d = ImageDraw.Draw(sheet)
    for i, mesh in enumerate(meshes):
        y = 10 + i * (th + label_h + 10)
        mine = [r for r in rows if r.mesh == mesh]
        first = mine[0]
        d.multiline_text((8, y), f"{mesh}\n{first.faces:,} faces\nstands for {first.placement.split(':')[0]}\n"
                                 f"eye {_vec(first.eye)}\nlight {_vec(first.light)}", fill="black", font=font)
        for j, r in enumerate(mine):
            x = margin + j * cell_w
            tile = Image.fromarray(r.image).resize((tw, th), Image.NEAREST)
            sheet.paste(tile, (x, y))
            diff = "-" if r.differ_from_basic is None else f"{r.differ_from_basic:,}"
            name = LABELS[r.program] + ("" if r.builder == "-" else f" ({r.builder})")
            d.multiline_text((x, y + th + 3), f"{name}\n{r.kind}\ndiffer from basic: {diff}",
                             fill="black", font=font)
    return _png(sheet)


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"
