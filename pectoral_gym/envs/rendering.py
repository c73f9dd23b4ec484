"""Top view of the tank with pygame (imported lazily, as in Gymnasium's classic-control envs).

Tank frame to screen: ``x_px = X * scale``, ``y_px = height - Y * scale`` (Y up on screen).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from gymnasium.error import DependencyNotInstalled

from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

if TYPE_CHECKING:
    from pectoral_gym.envs.core import EnvConfig, EnvCore

__all__ = ["FishRenderer", "BODY_COLOR", "NOSE_COLOR", "FIN_COLOR", "SCALE", "warn_no_render_mode"]

SCALE = 400.0  # px per metre: the 2.30 m x 1.15 m tank is 920 x 460 px
WATER_COLOR = (214, 234, 248)
WALL_COLOR = (40, 40, 40)
TRAIL_COLOR = (90, 120, 200)
BODY_COLOR = (230, 120, 30)
NOSE_COLOR = (150, 20, 20)
FIN_COLOR = (20, 110, 60)
TARGET_COLOR = (200, 30, 160)
PATH_COLOR = (160, 160, 160)


def _import_pygame():
    import os

    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # no banner on stdout
    try:
        import pygame
    except ImportError as e:
        raise DependencyNotInstalled(
            'pygame is not installed: run `pip install pygame` (or `pip install "gymnasium[classic-control]"`)'
        ) from e
    return pygame


def warn_no_render_mode(env_id: str, maker: str = "gym.make") -> None:
    """Gymnasium's warning for ``render()`` without a render mode, its example naming ``env_id`` and ``maker``."""
    from gymnasium import logger

    logger.warn(
        "You are calling render method without specifying any render mode. You can specify the "
        f'render_mode at initialization, e.g. {maker}("{env_id}", render_mode="rgb_array")'
    )


class FishRenderer:
    """Draws one environment of an :class:`~pectoral_gym.envs.core.EnvCore`.

    Args:
        render_mode: ``"rgb_array"`` (an off-screen surface, no display needed) or ``"human"`` (a window).
        fps: Frame rate of the ``human`` window.
    """

    def __init__(self, render_mode: str, fps: float):
        self.pygame = _import_pygame()
        self.render_mode = render_mode
        self.fps = fps
        self.width = int(round(TANK_LENGTH * SCALE))
        self.height = int(round(TANK_WIDTH * SCALE))
        self.window = None
        self.clock = None
        self.surface = None

    def _px(self, x: float, y: float) -> tuple[float, float]:
        return x * SCALE, self.height - y * SCALE

    def render(self, core: EnvCore, i: int, trail: list[tuple[float, float]], config: EnvConfig):
        """Draw env ``i``; returns an ``(H, W, 3)`` uint8 array for ``rgb_array``, ``None`` for ``human``."""
        pg = self.pygame
        if self.surface is None:
            self.surface = pg.Surface((self.width, self.height))
        surf = self.surface
        surf.fill(WATER_COLOR)
        pg.draw.rect(surf, WALL_COLOR, pg.Rect(0, 0, self.width, self.height), width=3)
        target = self._px(*core.target(i))
        ellipse = core.reference(i)  # all zero unless the task moves its target along an ellipse (track)
        if not (ellipse.a > 0 and ellipse.b > 0):
            center = target
            pg.draw.circle(surf, TARGET_COLOR, center, max(2.0, config.goal_radius * SCALE), width=2)
            pg.draw.circle(surf, TARGET_COLOR, center, 3)
        else:
            a, b = ellipse.a * SCALE, ellipse.b * SCALE
            cx, cy = self._px(ellipse.cx, ellipse.cy)
            pg.draw.ellipse(surf, PATH_COLOR, pg.Rect(cx - a, cy - b, 2 * a, 2 * b), width=1)
            pg.draw.circle(surf, TARGET_COLOR, target, 5)
        if len(trail) >= 2:
            pg.draw.lines(surf, TRAIL_COLOR, False, [self._px(x, y) for x, y in trail], width=2)
        self._draw_fish(core, i)
        if self.render_mode == "human":
            if self.window is None:
                pg.display.init()  # the display only: pg.init() would open the audio device (ALSA errors headless)
                self.window = pg.display.set_mode((self.width, self.height))
                pg.display.set_caption("pectoral-gym")
                self.clock = pg.time.Clock()
            self.window.blit(surf, (0, 0))
            pg.event.pump()
            pg.display.flip()
            self.clock.tick(self.fps)
            return None
        return np.transpose(np.array(pg.surfarray.pixels3d(surf)), axes=(1, 0, 2))

    def _draw_fish(self, core: EnvCore, i: int) -> None:
        pg = self.pygame
        params = core.params[i]
        x, y, psi = core.fish_state(i)[:3]
        c, s = math.cos(psi), math.sin(psi)

        def to_px(bx: float, by: float) -> tuple[float, float]:  # body frame -> screen
            return self._px(x + c * bx - s * by, y + s * bx + c * by)

        half_length = 0.5 * params.body_length
        half_width = params.fin_offset  # the fin pivots sit on the body outline
        outline = [to_px(half_length * math.cos(t), half_width * math.sin(t))
                   for t in np.linspace(0.0, 2.0 * math.pi, 40, endpoint=False)]
        pg.draw.polygon(surf := self.surface, BODY_COLOR, outline)
        pg.draw.circle(surf, NOSE_COLOR, to_px(0.8 * half_length, 0.0), 4)
        angles, _ = core.model.fin_angles()
        for side, g in ((-1.0, angles[i, 0]), (1.0, angles[i, 1])):  # right fin at y = -C_p, left at +C_p
            pivot = (0.0, side * params.fin_offset)
            tip = (params.fin_span * math.cos(g), side * params.fin_offset + side * params.fin_span * math.sin(g))
            pg.draw.line(surf, FIN_COLOR, to_px(*pivot), to_px(*tip), width=3)

    def close(self) -> None:
        """Close the window (the display module is the only one started)."""
        if self.window is not None:
            self.pygame.display.quit()
            self.window = None
