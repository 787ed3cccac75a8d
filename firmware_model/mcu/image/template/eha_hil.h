/* eha-hil firmware interface: what the harness gives a Cortex-M4F image (docs/mcu.md,
 * "Firmware images in the loop"). The harness checks every access against this map and
 * stops the run with one line (address, PC, symbol) at the first access outside it.
 *
 * Memory map (STM32F405 as on the MCU board):
 *   0x0800_0000  1 MiB     flash: code, rodata, .data load image           read/execute
 *   0x080E_0000  128 KiB   calibration block (flash sector 11), written by  read
 *                          the harness before reset: eha_cal_header, then
 *                          the law's mcu_config record (mcu_law.h)
 *   0x1000_0000  64 KiB    CCM RAM (data only)                              read/write
 *   0x2000_0000  128 KiB   SRAM (stack, .data, .bss)                        read/write
 *   0x4000_0000  1 KiB     TIM2 registers (accepted, no effect)             read/write
 *   0x4002_3800  1 KiB     RCC registers (accepted, no effect)              read/write
 *   0x6000_0000  640 B     dual-port RAM on FSMC bank 1 (NE1), 16-bit words: word a at
 *                          0x6000_0000 + 2a; board k block at 0x40 k words:
 *                          +0x00..0x0F downstream (read/write), +0x10..0x1F reserved
 *                          (no access), +0x20..0x3F upstream (read only)
 *   0x6000_0400  20 B      MCU-board FPGA: board k's upstream CRC error count at
 *                          0x6000_0400 + 4k (read only)
 *   0x6400_0000  64 B      process data from the fieldbus (eha_rx, read only)
 *   0x6400_0100  256 B     process data to the fieldbus (eha_tx, write; read back)
 *   0xE000_E000  4 KiB     system control space: CPACR, NVIC, SysTick      read/write
 *                          (accepted, no effect; the FPU is always on)
 *
 * The 5 kHz entry: a global function `eha_hil_step` if the image has one, else the TIM2
 * interrupt handler, vector 44 of the table at 0x0800_0000. The harness boots the image
 * from the reset vector until it executes WFI (or the reset handler returns), then calls
 * the entry once per 200 us cycle on the stack main left, with LR set to a return address
 * of its own: the entry must return. Between cycles the harness copies the link's
 * upstream words into the DPRAM before the entry and the downstream words out after it.
 */
#ifndef EHA_HIL_H
#define EHA_HIL_H

#include <stdint.h>

#define EHA_FLASH_BASE 0x08000000u
#define EHA_CAL_BASE 0x080E0000u
#define EHA_CCM_BASE 0x10000000u
#define EHA_SRAM_BASE 0x20000000u
#define EHA_DPRAM_BASE 0x60000000u
#define EHA_LINK_COUNTERS 0x60000400u
#define EHA_RX_BASE 0x64000000u
#define EHA_TX_BASE 0x64000100u

/* The dual-port RAM (firmware_model/mcu/dpram.py): 16-bit words. */
#define EHA_BOARD_STRIDE 0x40u
#define EHA_DOWN_OFFSET 0x00u
#define EHA_UP_OFFSET 0x20u
#define EHA_DPRAM ((volatile uint16_t *)EHA_DPRAM_BASE)
#define EHA_DOWN(k) (EHA_DPRAM + EHA_BOARD_STRIDE * (k) + EHA_DOWN_OFFSET)
#define EHA_UP(k) (EHA_DPRAM + EHA_BOARD_STRIDE * (k) + EHA_UP_OFFSET)
#define EHA_UP_CRC_ERRORS(k) (((volatile const uint32_t *)EHA_LINK_COUNTERS)[k])

/* Driver-board registers (firmware_model/fpga/layout.py; docs/fpga.md has them all):
 * word offsets inside a board's downstream and upstream blocks. */
#define EHA_D_CONTROL 0x00      /* 1 enable, 2 clear fault, 0 off */
#define EHA_D_MODE 0x01         /* 1 current control */
#define EHA_D_IQ_REF 0x02       /* q-axis current reference, mA, signed */
#define EHA_D_VQ_FF 0x04        /* q-axis voltage feed-forward, mV, signed */
#define EHA_D_ANGLE_OFFSET 0x09 /* rotor angle offset, sent at enable */
#define EHA_D_SEQUENCE 0x0C     /* counts the MCU's cycles */
#define EHA_U_STATUS 0x00       /* board status bits */
#define EHA_U_SPEED 0x04        /* motor speed, counts, signed */
#define EHA_U_PISTON_LO 0x06    /* BiSS piston count, low and high half */
#define EHA_U_PISTON_HI 0x07
#define EHA_U_IQ 0x08           /* measured q-axis current, mA, signed */
#define EHA_U_ERR_LINK_CRC 0x1A /* the board's downstream CRC error count */
#define EHA_CTRL_ENABLE 1u
#define EHA_CTRL_CLEAR_FAULT 2u
#define EHA_BOARD_MODE_CURRENT 1u

/* The calibration block's header; the record follows it at EHA_CAL_BASE + 16. */
#define EHA_CAL_MAGIC 0x4C414345u /* "ECAL" */
typedef struct {
    uint32_t magic;
    uint32_t version; /* 1 */
    uint32_t size;    /* bytes of the record that follows */
    uint32_t boards;  /* driver boards this MCU serves */
} eha_cal_header;
#define EHA_CAL ((const eha_cal_header *)EHA_CAL_BASE)

/* The calibration record (the law's mcu_config, firmware_model/mcu/c/mcu_law.h; the
 * project's image checks at compile time that the two agree field by field). Floats are
 * float32 in SI units; the analog arrays are in the order of the board's analog inputs:
 * p_acc, p_pump_a, p_pump_b, p_cyl_a, p_cyl_b, temperature, rod_temperature. */
#define EHA_N_ANALOG 7
typedef struct {
    float adc_lsb_v;       /* V per ADC code */
    float kc;              /* effective piston area [m^2]: force = kc * (p_a - p_b) */
    float rad_per_count, m_per_rad, n_per_code, m_per_count, rad_per_ssi, a_per_ma;
    int32_t strain_mid, biss_zero;
    uint32_t analog_register[EHA_N_ANALOG]; /* upstream word of each analog input */
    float analog_v0[EHA_N_ANALOG];          /* SI value = (V - v0) * mul / div */
    float analog_mul[EHA_N_ANALOG];
    float analog_div[EHA_N_ANALOG];
    float dt;                               /* the cycle [s] (200e-6) */
    float kt_eq;                            /* N per A of q-axis current */
    float kp, kd, derivative_a, observer_j, observer_ko, bemf;
    float vel_kp, vel_ki, force_kp, force_ki, highpass_a, seal_a, k_pos, cos_alpha;
    float f_lim, p_lim, i_lim, vq_ff_max;   /* N, Pa, A, V */
    uint32_t velocity_based, feedback;
    int32_t timeout_ticks, off_ticks;       /* command watchdog, in 20 kHz ticks */
    uint16_t down_init[16];                 /* the downstream words at boot */
} eha_cal;
#define EHA_CAL_RECORD ((const eha_cal *)(EHA_CAL_BASE + sizeof(eha_cal_header)))

/* Process data from the PC (one actuator), as the fieldbus left it before this cycle. */
#define EHA_RX_COMMAND 0x01u     /* a fresh command (mode, value) this cycle */
#define EHA_RX_ENABLE 0x02u      /* enable: boot the board with angle_offset */
#define EHA_RX_DISABLE 0x04u     /* disable */
#define EHA_RX_CLEAR_FAULT 0x08u /* clear the board's fault */
#define EHA_RX_GAINS 0x10u       /* kp_position, kp_force from the PC (0: the firmware's) */
enum { EHA_MODE_OFF = 0, EHA_MODE_FORCE = 1, EHA_MODE_POSITION = 2 };
typedef struct {
    int32_t tick;          /* the harness's 20 kHz tick at this cycle (4 per cycle) */
    uint32_t flags;        /* EHA_RX_*: what arrived since the last cycle */
    uint32_t mode;         /* EHA_MODE_* of the last command */
    float value;           /* force [N] or position [m] of the last command */
    float kp_position;
    float kp_force;
    uint32_t angle_offset; /* with EHA_RX_ENABLE */
    uint32_t reserved;
} eha_rx;
#define EHA_RX ((volatile const eha_rx *)EHA_RX_BASE)

/* Process data to the PC: the status word and the values the harness logs and probes
 * (mcu_output of mcu_law.h from its `status` field on). An image may leave any at 0. */
typedef struct {
    uint32_t status;
    float i_ref, v_ff, tau_ref, tau_p, f_fb, f_fil, f_strain;
    float observer_r, observer_total, derivative_y, highpass_y, seal_y;
    float force_integral, velocity_integral;
    float m_analog[7];
    float f_pres, tau_q, f_strain_raw, omega_m, v_pump, x_piston, iq, theta_rotor;
} eha_tx;
#define EHA_TX ((volatile eha_tx *)EHA_TX_BASE)

/* Vector 44: TIM2, the 5 kHz cycle timer on the real board. */
#define EHA_TIM2_VECTOR 44u

#endif
