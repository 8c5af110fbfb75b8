"""What the demo window draws (tkinter canvas, refreshed at 30 Hz).

Plate modes (scrape, roll): the 0.6 x 0.45 m simply supported steel plate, shaded by its
modal texture (the summed |mode shape| of its 12 lowest modes, sin(m pi x / a)
sin(n pi y / b), over the plate) with the probe's track across it coloured by how
strongly each point excites the plate (the model's gains there); drill mode: a slice of
the bone phantom's voxels through the burr (grey = density, updated as bone is
removed); poke mode: the soft ball in side view, its outline pushed in where the probe
sphere presses. Over that: the probe, the contact point while touching, the force vector
(length proportional to the haptic force the device is playing), and meters: audio
level, underruns, latency and mode.
"""

from __future__ import annotations

import math

import numpy as np

#: Canvas size (px), plate rectangle (px), force arrow scale (px per N) and longest arrow.
WIDTH, HEIGHT = 640, 440
PLATE = (80, 20, 560, 380)
ARROW_PX_PER_N, ARROW_MAX_PX = 40.0, 120.0
PLATE_SIZE = (0.6, 0.45)  # m, as patches.models_surface.steel_plate_model
TRACK = ((0.12, 0.3), (0.88, 0.62))  # its track, in fractions of the plate's sides
REFRESH_MS = 33
#: Poke mode: the ball's centre on the canvas (px) and the scale (px per m).
BALL_CENTRE, BALL_SCALE = (320, 250), 2800.0


def plate_texture(width: int, height: int, modes: int = 12) -> np.ndarray:
    """(height, width, 3) uint8: the summed |shape| of the plate's lowest ``modes``
    simply supported modes (frequency ~ (m/a)^2 + (n/b)^2), dark blue to light steel."""
    a, b = PLATE_SIZE
    pairs = sorted(((m / a) ** 2 + (n / b) ** 2, m, n) for m in range(1, 8) for n in range(1, 8))[:modes]
    x = (np.arange(width) + 0.5) / width
    y = (np.arange(height) + 0.5) / height
    field = np.zeros((height, width))
    for _, m, n in pairs:
        field += np.abs(np.outer(np.sin(n * np.pi * y), np.sin(m * np.pi * x)))
    field /= field.max()
    low, high = np.array([40, 52, 72]), np.array([196, 208, 220])
    return (low + field[..., None] * (high - low)).astype(np.uint8)


def track_strength(points: int = 9) -> np.ndarray:
    """Relative excitation (0..1) at each of the plate model's track points: the root
    sum of squares of its modal gains there."""
    from patches.models_surface import steel_plate_model

    gains = steel_plate_model().gains[:points]
    strength = np.sqrt(np.sum(gains**2, axis=1))
    return strength / strength.max()


def photo(tk, rgb: np.ndarray):
    """A Tk PhotoImage from an (h, w, 3) uint8 array (via PPM, no imaging library)."""
    h, w, _ = rgb.shape
    return tk.PhotoImage(data=b"P6 %d %d 255\n" % (w, h) + rgb.tobytes(), format="PPM")


def level_dbfs(engine) -> float:
    """RMS level of the first audio channel over the last 50 ms the device played."""
    heard, _ = engine.monitor()
    tail = heard[0, -2400:] if heard.shape[1] else np.zeros(1)
    rms = float(np.sqrt(np.mean(tail**2))) if tail.size else 0.0
    return 20 * math.log10(rms) if rms > 1e-9 else -180.0


class DemoView:
    """The canvas, its drawing and the pointer bindings for one mode."""

    def __init__(self, root, mode: str, engine, probe):
        import tkinter as tk

        self.tk, self.root, self.mode, self.engine, self.probe = tk, root, mode, engine, probe
        what = {
            "drill": "hold to drill into a bone phantom",
            "poke": "hold to press into a soft ball, drag to slide over it",
        }.get(mode, f"click to tap, drag to {mode}")
        root.title(f"jassy demo, {mode} mode: {what}")
        root.geometry("+0+0")
        self.canvas = tk.Canvas(root, width=WIDTH, height=HEIGHT, background="#20262e", highlightthickness=0)
        self.canvas.pack()
        self._image = None
        if mode == "drill":
            self._voxel_scale = 4
            self._draw_bone()
        elif mode == "poke":
            cx, cy = BALL_CENTRE
            base = cy + 0.8 * self.probe.radius * BALL_SCALE  # the rigid base under the ball
            self.canvas.create_rectangle(cx - 200, base, cx + 200, base + 12, fill="#5a6068", outline="")
        else:
            self._draw_plate()
        self.meters = self.canvas.create_text(
            8, HEIGHT - 8, anchor="sw", fill="#e8e8e8", font=("TkFixedFont", 10), text=""
        )
        self.items: list[int] = []
        self.root.after(REFRESH_MS, self.refresh)

    # ----------------------------------------------------------------- geometry
    def track_point(self, x: float) -> tuple[float, float]:
        """Canvas position of track fraction x on the plate."""
        (u0, v0), (u1, v1) = TRACK
        u, v = u0 + (u1 - u0) * x, v0 + (v1 - v0) * x
        left, top, right, bottom = PLATE
        return left + u * (right - left), bottom - v * (bottom - top)

    def fraction(self, px: float, py: float) -> float:
        """Track fraction nearest to canvas point (px, py) (plate modes) or the pointer's
        share of the bone slice's width (drill)."""
        if self.mode == "drill":
            nx = self.probe.volume.density.shape[0] * self._voxel_scale
            return min(max((px - self._bone_left) / nx, 0.0), 1.0)
        if self.mode == "poke":  # the polar angle of the pointer over the ball, -45..45 degrees
            angle = math.degrees(math.atan2(px - BALL_CENTRE[0], BALL_CENTRE[1] - py))
            return min(max(angle / 90.0 + 0.5, 0.0), 1.0)
        (x0, y0), (x1, y1) = self.track_point(0.0), self.track_point(1.0)
        dx, dy = x1 - x0, y1 - y0
        return min(max(((px - x0) * dx + (py - y0) * dy) / (dx * dx + dy * dy), 0.0), 1.0)

    # ------------------------------------------------------------------ drawing
    def _draw_plate(self) -> None:
        left, top, right, bottom = PLATE
        self._image = photo(self.tk, plate_texture(right - left, bottom - top))
        self.canvas.create_image(left, top, anchor="nw", image=self._image)
        self.canvas.create_rectangle(left, top, right, bottom, outline="#f0f0f0", width=2)
        strength = track_strength()
        for k in range(strength.size - 1):
            (xa, ya), (xb, yb) = self.track_point(k / 8), self.track_point((k + 1) / 8)
            level = int(80 + 175 * (strength[k] + strength[k + 1]) / 2)
            self.canvas.create_line(xa, ya, xb, yb, fill=f"#{level:02x}{level // 2:02x}20", width=6)

    def _draw_bone(self) -> None:
        density = self.probe.volume.density
        nx, _, nz = density.shape
        self._bone_left = (WIDTH - nx * self._voxel_scale) // 2
        self._bone_top = 20
        self._image = self.tk.PhotoImage(width=nx * self._voxel_scale, height=nz * self._voxel_scale)
        self.canvas.create_image(self._bone_left, self._bone_top, anchor="nw", image=self._image)
        self._update_bone()

    def _update_bone(self) -> None:
        density = self.probe.volume.density
        ny = density.shape[1]
        cut = density[:, ny // 2, ::-1].T  # rows from the top (z up)
        grey = np.repeat(np.repeat(cut, self._voxel_scale, 0), self._voxel_scale, 1)
        rgb = np.stack([grey, (grey * 0.92).astype(np.uint8), (grey * 0.8).astype(np.uint8)], axis=-1)
        rgb[grey == 0] = (32, 38, 46)
        self._image.configure(data=b"P6 %d %d 255\n" % (rgb.shape[1], rgb.shape[0]) + rgb.tobytes())

    def _burr_position(self) -> tuple[float, float, float]:
        """Canvas (x, y, radius) of the burr."""
        volume, s = self.probe.volume, self._voxel_scale
        nz = volume.density.shape[2]
        if self.probe.controller is not None:
            centre = self.probe.controller.pos
        else:
            centre = self.probe._world(self.probe.x)
        i, _, k = (np.asarray(centre) - volume.origin) / volume.voxel
        radius = self.probe.sim.params.radius / volume.voxel * s
        return self._bone_left + i * s, self._bone_top + (nz - 1 - k) * s, radius

    def _ball_outline(self) -> list[float]:
        """Canvas points of the ball's outline (y = 0 section), pushed onto the probe
        sphere's surface where they would lie inside it."""
        probe, (cx, cy) = self.probe, BALL_CENTRE
        centre = np.array([probe.centre[0], probe.centre[2]])
        points = []
        for phi in np.linspace(0.0, 2 * np.pi, 181):
            p = probe.radius * np.array([math.sin(phi), math.cos(phi)])
            d = p - centre
            gap = float(np.hypot(*d))
            if gap < probe.probe_radius:
                p = centre + d / max(gap, 1e-12) * probe.probe_radius
            points += [cx + p[0] * BALL_SCALE, cy - p[1] * BALL_SCALE]
        return points

    def _refresh_poke(self, magnitude: float) -> None:
        c, probe, (cx, cy) = self.canvas, self.probe, BALL_CENTRE
        self.items.append(c.create_polygon(self._ball_outline(), fill="#c0504d", outline="#f0d0c8", width=2))
        x, y = cx + probe.centre[0] * BALL_SCALE, cy - probe.centre[2] * BALL_SCALE
        r = probe.probe_radius * BALL_SCALE
        self.items.append(c.create_oval(x - r, y - r, x + r, y + r, outline="#ffd040", width=3))
        if probe.touching:
            n = probe.force / max(float(np.linalg.norm(probe.force)), 1e-12)  # on the probe, outwards
            tip = (x - n[0] * r, y + n[2] * r)
            self.items.append(c.create_oval(tip[0] - 4, tip[1] - 4, tip[0] + 4, tip[1] + 4, fill="#ff4040"))
            arrow = min(magnitude * ARROW_PX_PER_N / 4, ARROW_MAX_PX)
            end = (tip[0] + n[0] * arrow, tip[1] - n[2] * arrow)
            self.items.append(c.create_line(*tip, *end, fill="#40ff80", width=3, arrow="last"))

    def refresh(self) -> None:
        for item in self.items:
            self.canvas.delete(item)
        self.items.clear()
        force = self.engine.haptic_now()
        magnitude = float(np.linalg.norm(force)) if force.size else 0.0
        arrow = min(magnitude * ARROW_PX_PER_N, ARROW_MAX_PX)
        c = self.canvas
        if self.mode == "poke":
            self._refresh_poke(magnitude)
        elif self.mode == "drill":
            self._update_bone()
            x, y, r = self._burr_position()
            self.items.append(c.create_oval(x - r, y - r, x + r, y + r, outline="#ffd040", width=3))
            if self.probe.touching:
                tip = y + r
                self.items.append(c.create_oval(x - 4, tip - 4, x + 4, tip + 4, fill="#ff4040", outline=""))
                self.items.append(
                    c.create_line(x, tip, x, tip - arrow, fill="#40ff80", width=3, arrow="last")
                )
        else:
            x, y = self.track_point(self.probe.x)
            lift = 0 if self.probe.touching else 14
            self.items.append(
                c.create_oval(x - 9, y - 9 - lift, x + 9, y + 9 - lift, outline="#ffd040", width=3)
            )
            if self.probe.touching:
                self.items.append(c.create_oval(x - 4, y - 4, x + 4, y + 4, fill="#ff4040", outline=""))
                self.items.append(c.create_line(x, y, x, y + arrow, fill="#40ff80", width=3, arrow="last"))
        stats = self.engine.stats()
        c.itemconfigure(
            self.meters,
            text=f"{self.mode}  level {level_dbfs(self.engine):6.1f} dBFS  force {magnitude:5.2f} N  "
            f"underruns {stats.underrun_callbacks}  latency {stats.latency * 1e3:.2f} ms",
        )
        self.root.after(REFRESH_MS, self.refresh)

    # -------------------------------------------------------------------- input
    def bind_pointer(self) -> None:
        c, probe = self.canvas, self.probe
        c.bind("<ButtonPress-1>", lambda e: probe.press(self.fraction(e.x, e.y), e.time / 1000.0))
        c.bind("<B1-Motion>", lambda e: probe.move(self.fraction(e.x, e.y), e.time / 1000.0))
        c.bind("<ButtonRelease-1>", lambda e: probe.release(e.time / 1000.0))

        def hover(e) -> None:
            if not probe.touching:
                probe.x = self.fraction(e.x, e.y)

        c.bind("<Motion>", hover)
