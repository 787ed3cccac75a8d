"""The LVDS link between the MCU board and a driver board: its endpoints, word timing and
fault injection (:mod:`firmware_model.lvds.link`); the word codec is
:mod:`protocols.lvds`."""
