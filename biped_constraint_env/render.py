"""Stick-figure drawing (no physics). Pillow draws the frames; matplotlib shows the window.

Both are optional (``pip install biped-constraint-env[plot]``) and imported lazily.
"""

from __future__ import annotations

import numpy as np
from gymnasium.error import DependencyNotInstalled

from .modes import Mode

FRAME_WIDTH_PX = 480
FRAME_HEIGHT_PX = 360
PIXELS_PER_M = 70.0
GROUND_MARGIN_PX = 40
CONTACTS_BY_MODE = {
    Mode.FOOT_FLAT: ("stance_toe", "stance_heel"),
    Mode.TOE_PIVOT: ("stance_toe",),
    Mode.TOE_HEEL: ("stance_toe", "swing_heel"),
    Mode.DOUBLE_SUPPORT: ("stance_toe", "stance_heel", "swing_toe"),
}
"""Active ground contacts drawn as red markers in each model."""
_LEG_COLOURS = ((40, 90, 200), (220, 120, 20))  # leg A blue, leg B orange


class Renderer:
    """Draws frames of FRAME_HEIGHT_PX x FRAME_WIDTH_PX x 3 (uint8); the camera follows the hip."""

    def __init__(self):
        """Check that Pillow is importable."""
        try:
            from PIL import Image, ImageDraw  # noqa: F401
        except ImportError as e:  # pragma: no cover - depends on the installation
            raise DependencyNotInstalled(
                "rendering needs Pillow: pip install 'biped-constraint-env[plot]'"
            ) from e
        self._fig = None

    def frame(
        self,
        pts: dict[str, np.ndarray],
        mode: int,
        t: float,
        stance_side: int,
        steps: int,
        slope_rad: float = 0.0,
    ) -> np.ndarray:
        """RGB frame of the keypoints ``pts`` (the ground's y, z [m]) with model and time.

        On a slope the picture is turned by it (gravity points down the frame): the ground
        rises to the right by ``slope_rad``.
        """
        from PIL import Image, ImageDraw

        img = Image.new("RGB", (FRAME_WIDTH_PX, FRAME_HEIGHT_PX), (250, 250, 250))
        d = ImageDraw.Draw(img)
        c, s = np.cos(slope_rad), np.sin(slope_rad)
        hip = pts["hip"]
        ground = FRAME_HEIGHT_PX - GROUND_MARGIN_PX

        def px(p):  # the ground's frame turned to the world's, centred on the hip's place
            y, z = p[0] - hip[0], p[1]
            return (FRAME_WIDTH_PX / 2 + (c * y - s * z) * PIXELS_PER_M,
                    ground - (s * y + c * z) * PIXELS_PER_M)  # fmt: skip

        d.line([px((hip[0] - 8, 0.0)), px((hip[0] + 8, 0.0))], fill=(90, 90, 90), width=2)
        for k in range(int(np.floor(hip[0] - 4)), int(np.ceil(hip[0] + 4)) + 1):  # 1 m ticks
            x, y = px((k, 0.0))
            d.line([(x, y), (x - 6, y + 8)], fill=(150, 150, 150), width=1)
        for leg, role in ((stance_side, "stance"), (1 - stance_side, "swing")):
            chain = [f"{role}_toe", f"{role}_heel", f"{role}_ankle", f"{role}_toe"]
            colour = _LEG_COLOURS[leg]
            d.line([px(pts[n]) for n in chain], fill=colour, width=4)
            d.line(
                [px(pts[n]) for n in (f"{role}_ankle", f"{role}_knee", "hip")], fill=colour, width=5
            )
        for name in CONTACTS_BY_MODE[Mode(mode)]:
            x, y = px(pts[name])
            d.ellipse([x - 5, y - 5, x + 5, y + 5], fill=(210, 30, 30))
        d.text((10, 10), f"model {int(mode)}   t = {t:5.2f} s   steps {steps}", fill=(0, 0, 0))
        return np.asarray(img, dtype=np.uint8)

    def show(self, frame: np.ndarray, pause_s: float) -> None:
        """Show a frame in a matplotlib window."""
        try:
            import matplotlib.pyplot as plt
        except ImportError as e:  # pragma: no cover
            raise DependencyNotInstalled("render_mode='human' needs matplotlib") from e
        if self._fig is None:
            self._fig, ax = plt.subplots()
            ax.set_axis_off()
            self._im = ax.imshow(frame)
        else:
            self._im.set_data(frame)
        plt.pause(pause_s)

    def close(self) -> None:
        """Close the window."""
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None
