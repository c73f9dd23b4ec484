"""What a camera frame is rendered under: its imperfections (:class:`SceneConditions`) and occluders.

The settings of :func:`pectoral_gym.hardware.vision.scene.render_frame`, apart from the renderer: the emulated
camera, the tests and the studies state a scene through these without the drawing code. Colours are BGR uint8,
as OpenCV stores them; positions are in the tank frame [m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BLUE_BGR", "OCCLUDER_BGR", "RED_BGR", "Occluder", "SceneConditions"]

RED_BGR = (40, 35, 205)  # red marker, hue ~2 deg (OpenCV hue ~1)
BLUE_BGR = (190, 90, 25)  # blue marker, hue ~205 deg (OpenCV hue ~103)
OCCLUDER_BGR = (45, 45, 50)  # dark occluding object (a hand, a cable, its shadow)


@dataclass(frozen=True)
class Occluder:
    """A dark disc above the water in tank coordinates (a hand, a cable, a distractor if coloured).

    Attributes:
        x: Centre X [m].
        y: Centre Y [m].
        radius: Radius [m].
        bgr: Colour (BGR, 0-255); a red or blue one is a distracting blob for the tracker.
    """

    x: float
    y: float
    radius: float
    bgr: tuple[int, int, int] = OCCLUDER_BGR


@dataclass(frozen=True)
class SceneConditions:
    """Imperfections of a camera frame. The defaults are a mildly noisy, evenly lit, sharp frame.

    Attributes:
        noise_std: Standard deviation of additive Gaussian sensor noise [intensity units, 0-255].
        brightness: Overall gain of the lighting (1 = nominal; 0.5 = dim, 1.3 = bright).
        gradient: Relative gain change from the image centre to its edge along ``gradient_angle``
            (0.3: one side 30 % brighter, the other 30 % darker).
        gradient_angle: Direction of increasing light in the image [rad], 0 = towards +u.
        blur_sigma: Gaussian lens blur [px] (0 = sharp).
        front_occlusion: Fraction of the red marker's diameter hidden under a dark strip (0 none, 1 all).
        back_occlusion: Same for the blue marker.
        occluders: Extra discs drawn above the scene in tank coordinates.
        glare: Number of specular reflections (small white spots) at random places.
        red_bgr: Colour of the front marker (vary it to move its hue across 0/180).
        blue_bgr: Colour of the back marker.
    """

    noise_std: float = 2.0
    brightness: float = 1.0
    gradient: float = 0.0
    gradient_angle: float = 0.0
    blur_sigma: float = 0.0
    front_occlusion: float = 0.0
    back_occlusion: float = 0.0
    occluders: tuple[Occluder, ...] = ()
    glare: int = 0
    red_bgr: tuple[int, int, int] = RED_BGR
    blue_bgr: tuple[int, int, int] = BLUE_BGR

    def __post_init__(self) -> None:
        checks = (
            ("noise_std", self.noise_std >= 0),
            ("brightness", self.brightness > 0),
            ("gradient", 0 <= self.gradient < 1),
            ("blur_sigma", self.blur_sigma >= 0),
            ("front_occlusion", 0 <= self.front_occlusion <= 1),
            ("back_occlusion", 0 <= self.back_occlusion <= 1),
            ("glare", self.glare >= 0),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if not np.isfinite(value) or not ok:
                raise ValueError(f"SceneConditions.{name} out of range: {value!r}")

    @classmethod
    def clean(cls) -> SceneConditions:
        """A noise-free, evenly lit, sharp frame."""
        return cls(noise_std=0.0)
