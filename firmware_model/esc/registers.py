"""ESC register map (ETG.1000.4 / ETG.1000.6 register descriptions), AL states and codes.

Only the addresses this model implements are named; everything else in 0x0000..0x0FFF
reads as zero and ignores writes. Process-data RAM starts at :data:`RAM_START`.
"""

from __future__ import annotations

import enum

# --- identity (read only) -----------------------------------------------------------------
TYPE = 0x0000            # u8 ESC type
REVISION = 0x0001        # u8
BUILD = 0x0002           # u16
FMMUS_SUPPORTED = 0x0004  # u8
SMS_SUPPORTED = 0x0005   # u8
RAM_SIZE = 0x0006        # u8, KiB
PORT_DESCRIPTOR = 0x0007  # u8, 2 bits per port: 00 none, 01 not configured, 10 EBUS, 11 MII
FEATURES = 0x0008        # u16, bit 2: distributed clocks, bit 3: 64-bit DC
# --- addresses ----------------------------------------------------------------------------
STATION_ADDRESS = 0x0010  # u16 configured station address (FPxx)
STATION_ALIAS = 0x0012   # u16 (from SII word 4)
# --- data link ----------------------------------------------------------------------------
DL_CONTROL = 0x0100      # u32; bit 24: station alias enabled for FPxx
DL_STATUS = 0x0110       # u16 read only
# --- application layer --------------------------------------------------------------------
AL_CONTROL = 0x0120      # u16
AL_STATUS = 0x0130       # u16 read only
AL_STATUS_CODE = 0x0134  # u16 read only
PDI_CONTROL = 0x0140     # u8 (from SII word 0)
ESC_CONFIG = 0x0141      # u8
IRQ_MASK = 0x0200        # u16 ECAT event mask
# --- error counters (writing any byte clears all) ----------------------------------------------
RX_ERROR = 0x0300        # 0x0300..0x0313
ERROR_COUNTERS_END = 0x0314
# --- watchdogs ----------------------------------------------------------------------------
WD_DIVIDER = 0x0400      # u16: one watchdog increment = 40 ns * (divider + 2)
WD_TIME_PDI = 0x0410     # u16
WD_TIME_PD = 0x0420      # u16 process-data watchdog time in increments
WD_STATUS_PD = 0x0440    # u16 read only, bit 0: 1 = not expired
WD_COUNTER_PD = 0x0442   # u8 expirations (write clears)
WD_COUNTER_PDI = 0x0443  # u8
# --- SII EEPROM interface ----------------------------------------------------------------------
EEP_CONFIG = 0x0500      # u8 bit 0: PDI owns the EEPROM (1) / master (0)
EEP_PDI_ACCESS = 0x0501  # u8
EEP_CONTROL = 0x0502     # u16 command (bits 8..10) / status
EEP_ADDRESS = 0x0504     # u32 word address
EEP_DATA = 0x0508        # 4 or 8 bytes
EEP_END = 0x0510
# --- FMMUs and sync managers ---------------------------------------------------------------------
FMMU0 = 0x0600
FMMU_SIZE = 16
N_FMMU = 8
SM0 = 0x0800
SM_SIZE = 8
N_SM = 8
# --- distributed clocks (:mod:`firmware_model.esc.dc`) -------------------------------------------
DC_START = 0x0900
DC_RECV_TIME_P0 = 0x0900  # u32 x 4: local time a frame reached port 0..3; a write to 0x0900
#                           latches all four (and 0x0918) for that frame
DC_RECV_TIME_P1 = 0x0904
DC_SYSTEM_TIME = 0x0910   # u64 read: system time; write: compared by the time control loop
DC_RECV_TIME_PU = 0x0918  # u64 local time the latching frame reached the processing unit
DC_SYSTEM_OFFSET = 0x0920  # u64 system time = local time + offset
DC_SYSTEM_DELAY = 0x0928  # u32 propagation delay from the reference clock [ns]
DC_SYSTEM_DIFF = 0x092C   # u32 filtered difference, bit 31: local copy smaller than received
DC_SPEED_START = 0x0930   # u16 loop bandwidth; a write resets the loop
DC_SPEED_DIFF = 0x0932    # i16 the loop's frequency correction [0.1 ppm] (this model's unit)
DC_DIFF_FILTER = 0x0934   # u8 filter depth of the system time difference
DC_SPEED_FILTER = 0x0935  # u8 filter depth of the speed counter (stored)
DC_CYCLIC_CONTROL = 0x0980  # u8 bit 0: sync unit assigned to the PDI (then ECAT may not drive it)
DC_ACTIVATION = 0x0981    # u8 bit 0 cyclic operation, 1 SYNC0, 2 SYNC1, 5 start plausibility check
DC_ACTIVATION_STATUS = 0x0984  # u8 bit 0 SYNC0 running, bit 2 start time was not in the future
DC_START_TIME = 0x0990    # u64 write: SYNC0 start (system time); read: next SYNC0 pulse
DC_SYNC0_CYCLE = 0x09A0   # u32 [ns]; 0: one pulse
DC_SYNC1_CYCLE = 0x09A4   # u32 [ns] (stored; the box does not use SYNC1)
DC_END = 0x0A00
FEATURE_DC = 0x0004
FEATURE_DC64 = 0x0008
# --- process-data RAM ---------------------------------------------------------------------
RAM_START = 0x1000
MEMORY_SIZE = 0x2000     # registers + 4 KiB RAM

# EEPROM control/status bits (0x0502)
EEP_CMD_MASK = 0x0700
EEP_CMD_NOP = 0x0000
EEP_CMD_READ = 0x0100
EEP_CMD_WRITE = 0x0200
EEP_CMD_RELOAD = 0x0300
EEP_STAT_READ8 = 0x0040      # reads return 8 bytes
EEP_STAT_CMD_ERROR = 0x0800  # command error (e.g. write: EEPROM is read only here)
EEP_STAT_ERRORS = 0x7800
EEP_STAT_BUSY = 0x8000

# SM control byte (offset 4) and activate byte (offset 6)
SM_DIR_MASK = 0x0C
SM_DIR_READ = 0x00       # ECAT reads (slave inputs)
SM_DIR_WRITE = 0x04      # ECAT writes (slave outputs)
SM_WATCHDOG = 0x40       # a write of the buffer retriggers the process-data watchdog
SM_ENABLE = 0x01         # activate byte bit 0
# Mailbox sync managers (1-buffer mode): control bits 0..1 = 10; status byte (offset 5) bit
# 3 = mailbox full; activate byte (offset 6) bit 1 = repeat request (master toggles it after
# a lost read); PDI control byte (offset 7) bit 1 = repeat acknowledge (the slave's side).
SM_MODE_MASK = 0x03
SM_MODE_MAILBOX = 0x02
SM_STATUS = 5
SM_PDI_CONTROL = 7
SM_STATUS_FULL = 0x08
SM_REPEAT = 0x02

# FMMU type byte (offset 11)
FMMU_READ = 0x01
FMMU_WRITE = 0x02


class AlState(enum.IntEnum):
    """AL states (AL control / AL status bits 0..3)."""

    INIT = 0x1
    PREOP = 0x2
    BOOT = 0x3
    SAFEOP = 0x4
    OP = 0x8


AL_ERROR = 0x10          # AL status: error indicator; AL control: error acknowledge


class AlStatusCode(enum.IntEnum):
    """AL status codes this slave reports (ETG.1000.6 Table "AL Status Codes")."""

    NO_ERROR = 0x0000
    INVALID_STATE_CHANGE = 0x0011     # e.g. INIT -> OP
    UNKNOWN_STATE = 0x0012            # not one of 1, 2, 4, 8
    BOOTSTRAP_NOT_SUPPORTED = 0x0013
    INVALID_MAILBOX_CONFIG = 0x0016   # INIT -> PREOP: mailbox sync managers not as the SII
    SM_WATCHDOG = 0x001B              # process-data watchdog expired in OP
    INVALID_OUTPUT_CONFIG = 0x001D    # output sync manager / FMMU not as in the SII
    INVALID_INPUT_CONFIG = 0x001E     # input sync manager / FMMU not as in the SII
