/* The MCU's force-control law for one actuator, as STM32F4 firmware: C99, float32 only.
 *
 * One-to-one with the Python model in firmware_model/mcu/ (measure.py, filters.py,
 * controller.py, mcu.py, board.py's per-cycle process data): every float operation is the
 * same single-precision operation in the same order. Build with -ffp-contract=off (see
 * docs/mcu.md): a fused multiply-add rounds once where the model rounds twice.
 *
 * All records are little-endian and made of 4-byte fields (uint16 arrays in pairs), so the
 * same bytes are read by the host library (ctypes) and by the Cortex-M4 image (semihosting).
 */
#ifndef MCU_LAW_H
#define MCU_LAW_H

#include <stdint.h>

/* Upstream registers the law reads (firmware_model/fpga/layout.py). */
#define U_STATUS 0x00
#define U_SSI 0x02
#define U_SPEED 0x04
#define U_PISTON_LO 0x06
#define U_PISTON_HI 0x07
#define U_IQ 0x08
#define U_STRAIN_LO 0x11
#define U_STRAIN_HI 0x12
#define U_ERR_LINK_CRC 0x1A
#define UP_WORDS 32

/* Downstream registers it writes. */
#define D_CONTROL 0x00
#define D_MODE 0x01
#define D_IQ_REF 0x02
#define D_VQ_FF 0x04
#define D_ANGLE_OFFSET 0x09
#define D_SEQUENCE 0x0C
#define DOWN_WORDS 16

/* The board's status bits. */
#define ST_ENABLED 0x01u
#define ST_FAULT 0x02u
#define ST_LINK_LOST 0x08u
#define ST_ENCODER_ERROR 0x20u
#define ST_STRAIN_ERROR 0x40u

/* The MCU's status bits (docs/mcu.md). */
#define CMD_TIMEOUT 0x001u
#define SAFE_OFF 0x002u
#define FORCE_LIMITED 0x004u
#define CURRENT_LIMITED 0x008u
#define PRESSURE_HIGH 0x010u
#define BOARD_FAULT 0x020u
#define LINK_ERROR 0x040u
#define BOARD_ENABLED 0x080u
#define ENCODER_ERROR 0x100u
#define STRAIN_ERROR 0x200u

#define CRC_COUNT_MAX 0xFFFFu
#define CTRL_ENABLE 1u
#define CTRL_CLEAR_FAULT 2u
#define BOARD_MODE_CURRENT 1u

/* Analog inputs, in the order of layout.ANALOG_INPUTS. */
enum { A_P_ACC, A_P_PUMP_A, A_P_PUMP_B, A_P_CYL_A, A_P_CYL_B, A_TEMPERATURE,
       A_ROD_TEMPERATURE, N_ANALOG };

enum { MODE_OFF = 0, MODE_FORCE = 1, MODE_POSITION = 2 };
enum { FB_PRESSURE = 0, FB_STRAIN = 1, FB_COMPLEMENTARY = 2 };

/* The firmware calibration, as float32 constants (what a build would #define). */
typedef struct {
    /* measurements */
    float adc_lsb_v;
    float kc;
    float rad_per_count;
    float m_per_rad;
    float n_per_code;
    float m_per_count;
    float rad_per_ssi;
    float a_per_ma;
    int32_t strain_mid;
    int32_t biss_zero;
    uint32_t analog_register[N_ANALOG];
    float analog_v0[N_ANALOG];
    float analog_mul[N_ANALOG];
    float analog_div[N_ANALOG];
    /* controller */
    float dt;
    float kt_eq;
    float kp;
    float kd;
    float derivative_a;
    float observer_j;
    float observer_ko;
    float bemf;
    float vel_kp;
    float vel_ki;
    float force_kp;
    float force_ki;
    float highpass_a;
    float seal_a;
    float k_pos;
    float cos_alpha;
    float f_lim;
    float p_lim;
    float i_lim;
    float vq_ff_max;
    uint32_t velocity_based;
    uint32_t feedback;
    /* watchdog */
    int32_t timeout_ticks;
    int32_t off_ticks;
    uint16_t down_init[DOWN_WORDS];
} mcu_config;

/* What reaches the program in one 5 kHz cycle. */
#define IN_COMMAND 0x01u     /* a fresh command (mode, value), stamped with this tick */
#define IN_ENABLE 0x02u      /* rising enable: boot the board with angle_offset */
#define IN_DISABLE 0x04u     /* falling enable: control = 0 */
#define IN_CLEAR_FAULT 0x08u /* rising clear-fault: control = CLEAR_FAULT */
#define IN_GAINS 0x10u       /* kp_position, kp_force from the PC (0: the firmware's own) */

typedef struct {
    int32_t tick;
    uint32_t flags;
    uint32_t mode;
    float value;
    float kp_position;
    float kp_force;
    uint32_t up_crc_errors;
    uint32_t angle_offset;
    uint16_t up[UP_WORDS];
} mcu_input;

/* What it leaves after the cycle: the downstream words, the status word and every float it
 * holds (measurements and controller states), for a bit-for-bit comparison. */
typedef struct {
    uint16_t down[DOWN_WORDS];
    uint32_t status;
    float i_ref;
    float v_ff;
    float tau_ref;
    float tau_p;
    float f_fb;
    float f_fil;
    float f_strain;
    float observer_r;
    float observer_total;
    float derivative_y;
    float highpass_y;
    float seal_y;
    float force_integral;
    float velocity_integral;
    float m_analog[N_ANALOG];
    float f_pres;
    float tau_q;
    float f_strain_raw;
    float omega_m;
    float v_pump;
    float x_piston;
    float iq;
    float theta_rotor;
} mcu_output;

/* The program's state. */
typedef struct {
    mcu_config cfg;
    float kp;    /* current force gain (PC override or cfg.kp) */
    float k_pos; /* current position gain */
    /* measurements */
    float analog[N_ANALOG];
    float f_pres, tau_q, f_strain_raw, omega_m, v_pump, x_piston, iq, theta_rotor;
    uint32_t strain_samples, board_status;
    /* controller blocks */
    float lp_seal_y;
    float hp_y, hp_u_prev;
    int hp_started;
    float d_y, d_u_prev;
    float force_integral, velocity_integral;
    float obs_total, obs_p0, obs_r;
    int obs_started;
    float f_strain, tau_p, tau_used, f_fb, f_fil;
    int i_limited;
    uint32_t limits;
    /* program */
    uint32_t mode;
    float value;
    int32_t last_cmd_tick;
    uint32_t seq;
    uint32_t crc_seen_down, crc_seen_up;
    float tau_ref, i_ref, v_ff;
    uint32_t status;
    uint16_t down[DOWN_WORDS];
} mcu_state;

void mcu_law_init(mcu_state *s, const mcu_config *cfg);
void mcu_law_step(mcu_state *s, const mcu_input *in, mcu_output *out);
/* The output record of the state s (what mcu_law_step leaves in out after its step). */
void mcu_law_report(const mcu_state *s, mcu_output *out);
/* n steps from a fresh state: the host library's batch entry point. */
void mcu_law_run(const mcu_config *cfg, const mcu_input *in, uint32_t n, mcu_output *out);
/* One step of n independent programs (one per actuator): state k with in[k] and out[k].
 * The host's whole-robot engine calls this once per 5 kHz cycle for every actuator. */
void mcu_law_step_many(mcu_state *s, const mcu_input *in, uint32_t n, mcu_output *out);
/* sizeof mcu_config, mcu_input, mcu_output, mcu_state for which = 0, 1, 2, 3. */
uint32_t mcu_law_sizes(uint32_t which);

#endif
