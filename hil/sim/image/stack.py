"""A firmware image as the stack's MCU (``--set mcu.impl=image``): the calls and probed
values of :class:`hil.sim.mcu_c.CMcu`, with each cycle run by the image on the emulator. The
stack's link memory plays the DPRAM's board 0 (sync_up before the cycle, sync_down after
it: no added latency, as with the Python MCU)."""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga.driver_board import LinkMemory
from hil.sim.image import profile
from hil.sim.image.errors import ImageError, ImageFault
from hil.sim.image.law import ImageLaw
from hil.sim.mcu_builds import BuildError
from hil.sim.mcu_c import CMcu
from plant.config import Config, ConfigError

TICK_S = 1 / 20_000  # the harness's clock


class ImageMcu(CMcu):
    """One actuator's MCU program run by a firmware image."""

    impl = "image"

    def __init__(self, cfg: Config, links: list[LinkMemory]) -> None:
        self._path = cfg.get("mcu.image")
        super().__init__(cfg, links)

    def _start(self, cal: FirmwareCalibration, config: np.ndarray) -> None:
        path = self._path
        try:
            self._law = ImageLaw(path or None, config)
        except (ImageError, BuildError) as exc:
            raise ConfigError(f"mcu.impl = 'image': {exc}") from None
        except ImageFault as exc:
            raise ImageFault(f"mcu image {path or 'mcu_law_image.elf'}: {exc}") from None
        self._step = 0
        self.profile = self._law.profile
        profile.SESSION.append(self.profile)

    def _law_step(self, rec: np.ndarray, out: np.ndarray, link: LinkMemory) -> None:
        tick = int(rec["tick"])
        label = f"step {self._step} (t = {tick * TICK_S:.4f} s)"
        self._step += 1
        try:
            self._law.step(rec, out, label)
        except ImageFault as exc:
            raise ImageFault(f"mcu image {self._law.image.path.name}: {exc}") from None
        link.down[:] = out["down"]
