"""The PNG of grid cuts drawn as a pixel array (Pillow), without matplotlib.

``io.output.figure_spec`` says what: one image ("image": a 2D grid field) or the three central cuts
of a 3D field ("cuts"). Each panel shows phi in physical coordinates (square pixels, one length
scale for all panels: ``PANEL_PX`` pixels along the longest box side), each sample a block of
pixels centred on its node (nearest sample, as matplotlib's ``imshow`` of before), the zero level
in black (``skimage.measure.find_contours``, sub-sample accurate, the library the ``surface.ply``
already uses), axis names and tick values, a title per panel, the figure's title and a colorbar of
phi over [-1, 1] in matplotlib's ``RdBu_r`` (the ColorBrewer RdBu stops, reversed, quantised to 256
levels as matplotlib's colormaps are). Text is Pillow's bundled default font.

Why not matplotlib: its import (~0.35 s) and drawing (~0.15 s at 64^3) were a sixth of the whole
64^3 CLI solve; this draws the same content in ~0.02 s (Pillow's import 0.02 s). Meshes' 2D
triangles stay with matplotlib (``io.png``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

PANEL_PX = 300  # pixels along the longest box side of a panel
FONT_PX = 13
MARGIN = {"left": 52, "right": 20, "top": 56, "bottom": 44, "gap": 64, "bar": 14, "bar_labels": 58}
BLACK, WHITE = (0, 0, 0), (255, 255, 255)
# ColorBrewer RdBu (11 classes), matplotlib's "RdBu" from red (0) to blue (1); RdBu_r reverses it
RDBU = ("#67001f", "#b2182b", "#d6604d", "#f4a582", "#fddbc7", "#f7f7f7", "#d1e5f0", "#92c5de",
        "#4393c3", "#2166ac", "#053061")
LUT_LEVELS = 256  # matplotlib's colormap resolution


@lru_cache(maxsize=1)
def _lut() -> np.ndarray:
    """RdBu_r as a (256, 3) uint8 table: the stops linearly interpolated at i / 255 (matplotlib's
    LinearSegmentedColormap), as bytes by truncation of 255 * value (its ``to_rgba(bytes=True)``)."""
    stops = np.array([[int(h[i:i + 2], 16) / 255 for i in (1, 3, 5)] for h in RDBU[::-1]])
    t = np.linspace(0.0, 1.0, LUT_LEVELS)
    at = np.linspace(0.0, 1.0, len(stops))
    rgb = np.stack([np.interp(t, at, stops[:, c]) for c in range(3)], axis=1)
    return (rgb * 255).astype(np.uint8)


def colors(values: np.ndarray) -> np.ndarray:
    """RGB bytes of phi values on [-1, 1] (clipped), as matplotlib's RdBu_r with vmin -1, vmax 1."""
    x = np.nan_to_num((np.asarray(values, float) + 1.0) / 2.0, nan=0.0)  # NaN: never written (io.output)
    index = np.clip((x * LUT_LEVELS).astype(np.int64), 0, LUT_LEVELS - 1)
    return _lut()[index]


def _ticks(lo: float, hi: float, target: int = 5) -> np.ndarray:
    """Round tick values (steps 1, 2 or 5 times a power of ten) inside [lo, hi], about ``target``."""
    raw = (hi - lo) / target
    power = 10.0 ** np.floor(np.log10(raw))
    step = power * min((1, 2, 5, 10), key=lambda m: abs(m * power - raw))
    first = np.ceil(lo / step - 1e-9) * step
    return np.arange(first, hi + 1e-9 * step, step)


def _label(value: float) -> str:
    text = f"{value:.3g}"
    return "0" if text in ("-0", "0") else text


class _Panel:
    """One cut in the figure: its sample axes and its pixel box (left, top, width, height)."""

    def __init__(self, cut, lo, hi, endpoint: bool, scale: float):
        self.cut = np.asarray(cut, float)
        self.axes = [np.linspace(a, b, k, endpoint=endpoint) for a, b, k in zip(lo, hi, self.cut.shape)]
        self.step = [x[1] - x[0] if len(x) > 1 else 1.0 for x in self.axes]
        # the extent of the pixels: each sample's block centred on it
        self.lo = [x[0] - s / 2 for x, s in zip(self.axes, self.step)]
        self.hi = [x[-1] + s / 2 for x, s in zip(self.axes, self.step)]
        self.scale = scale  # pixels per unit length
        self.size = [max(1, int(round((b - a) * scale))) for a, b in zip(self.lo, self.hi)]
        self.left = self.top = 0

    def to_pixel(self, x: float, y: float) -> tuple[float, float]:
        return (self.left + (x - self.lo[0]) * self.scale, self.top + (self.hi[1] - y) * self.scale)

    def pixels(self) -> np.ndarray:
        """(height, width, 3) bytes: each pixel the colour of its nearest sample."""
        index = []
        for d in range(2):
            centre = self.lo[d] + (np.arange(self.size[d]) + 0.5) / self.scale
            index.append(np.clip(np.floor((centre - self.lo[d]) / self.step[d]).astype(int), 0, self.cut.shape[d] - 1))
        return colors(self.cut[np.ix_(index[0], index[1][::-1])].T)

    def zero_level(self) -> list[list[tuple[float, float]]]:
        """The phi = 0 lines as pixel polylines (linear interpolation between samples)."""
        from skimage import measure  # third-party, lazy (as for surface.ply): only a drawn figure needs it
        if not (np.nanmin(self.cut) < 0 < np.nanmax(self.cut)):
            return []
        lines = []
        for c in measure.find_contours(self.cut, 0.0):
            x = self.axes[0][0] + c[:, 0] * self.step[0]
            y = self.axes[1][0] + c[:, 1] * self.step[1]
            lines.append([self.to_pixel(a, b) for a, b in zip(x, y)])
        return lines


def _text(draw, xy, text, font, anchor="mm"):
    draw.text(xy, text, fill=BLACK, font=font, anchor=anchor)


def _vertical_text(image, xy, text: str, font) -> None:
    """``text`` rotated by 90 degrees, centred at ``xy`` of the Pillow ``image``."""
    from PIL import Image, ImageDraw  # third-party, lazy (as in ``draw``)
    box = font.getbbox(text)
    strip = Image.new("L", (box[2] - box[0] + 4, box[3] - box[1] + 4), 0)
    ImageDraw.Draw(strip).text((2 - box[0], 2 - box[1]), text, fill=255, font=font)
    strip = strip.rotate(90, expand=True)
    image.paste(Image.new("RGB", strip.size, BLACK), (int(xy[0] - strip.size[0] / 2), int(xy[1] - strip.size[1] / 2)),
                strip)


def layout(spec: dict) -> tuple[list[_Panel], tuple[int, int]]:
    """The panels of ``spec`` placed in the figure, and the figure's (width, height) in pixels."""
    if spec["kind"] == "image":
        cuts, lows, highs = [spec["field"]], [spec["lo"]], [spec["hi"]]
        endpoint = False
    else:
        cuts, lows, highs, endpoint = spec["cuts"], spec["lo"], spec["hi"], spec["endpoint"]
    longest = max(max(b - a for a, b in zip(lo, hi)) for lo, hi in zip(lows, highs))
    panels = [_Panel(c, lo, hi, endpoint, PANEL_PX / longest) for c, lo, hi in zip(cuts, lows, highs)]
    height = max(p.size[1] for p in panels)
    x = MARGIN["left"]
    for p in panels:
        p.left, p.top = x, MARGIN["top"] + (height - p.size[1]) // 2
        x += p.size[0] + MARGIN["gap"]
    width = x - MARGIN["gap"] + MARGIN["gap"] // 2 + MARGIN["bar"] + MARGIN["bar_labels"] + MARGIN["right"]
    return panels, (width, MARGIN["top"] + height + MARGIN["bottom"])


def draw(path, spec: dict) -> None:
    """Draw ``spec`` ("image" or "cuts", ``io.output.figure_spec``) into the PNG file ``path``."""
    # third-party, lazy: only a drawn figure needs Pillow (0.02-0.05 s at import, not for ``import vesicle_opt``)
    from PIL import Image, ImageDraw, ImageFont
    panels, (width, height) = layout(spec)
    image = Image.new("RGB", (width, height), WHITE)
    canvas = ImageDraw.Draw(image)
    font = ImageFont.load_default(size=FONT_PX)
    if spec["kind"] == "image":
        titles, names = [spec["title"]], [("x", "y")]
        bar_label = "phi (+1 inside, -1 outside)"
    else:
        titles, names = spec["labels"], spec["axis_names"]
        _text(canvas, (width // 2, 14), spec["title"], font)
        bar_label = "phi"
    for p, title, (xname, yname) in zip(panels, titles, names):
        image.paste(Image.fromarray(p.pixels()), (p.left, p.top))
        for line in p.zero_level():
            canvas.line(line, fill=BLACK, width=2)
        right, bottom = p.left + p.size[0], p.top + p.size[1]
        canvas.rectangle((p.left - 1, p.top - 1, right, bottom), outline=BLACK)
        for t in _ticks(p.lo[0], p.hi[0]):
            px = p.to_pixel(t, p.lo[1])[0]
            canvas.line((px, bottom, px, bottom + 4), fill=BLACK)
            _text(canvas, (px, bottom + 6), _label(t), font, "mt")
        for t in _ticks(p.lo[1], p.hi[1]):
            py = p.to_pixel(p.lo[0], t)[1]
            canvas.line((p.left - 5, py, p.left - 1, py), fill=BLACK)
            _text(canvas, (p.left - 7, py), _label(t), font, "rm")
        _text(canvas, ((p.left + right) / 2, bottom + 30), xname, font)
        _text(canvas, (p.left - 40, (p.top + bottom) / 2), yname, font)
        _text(canvas, ((p.left + right) / 2, p.top - 12), title, font, "ms")
    # the colorbar: phi from -1 (bottom) to 1 (top), ticks every 0.5
    top, bottom = panels[0].top, max(p.top + p.size[1] for p in panels)
    left = panels[-1].left + panels[-1].size[0] + MARGIN["gap"] // 2
    values = np.linspace(1.0, -1.0, bottom - top)
    image.paste(Image.fromarray(np.repeat(colors(values)[:, None, :], MARGIN["bar"], axis=1)), (left, top))
    canvas.rectangle((left - 1, top - 1, left + MARGIN["bar"], bottom), outline=BLACK)
    for t in (-1.0, -0.5, 0.0, 0.5, 1.0):
        py = top + (1.0 - t) / 2.0 * (bottom - top)
        canvas.line((left + MARGIN["bar"], py, left + MARGIN["bar"] + 4, py), fill=BLACK)
        _text(canvas, (left + MARGIN["bar"] + 6, py), _label(t), font, "lm")
    _vertical_text(image, (left + MARGIN["bar"] + 44, (top + bottom) / 2), bar_label, font)
    image.save(path, format="PNG", compress_level=1)
