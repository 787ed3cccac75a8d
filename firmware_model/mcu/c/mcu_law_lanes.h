/* The MCU law of up to MCU_LW actuators stepped together (the host's whole-robot engine):
 * the programs' states in structure of arrays, one lane per actuator, for as long as the
 * engine holds the batch (loaded from the per-actuator mcu_state records when it claims
 * the batch, stored back when it lets it go).
 *
 * Each lane does the float32 operations of mcu_law_step (mcu_law.c) in the same order,
 * with the same roundings: a branch of the scalar law becomes a select between lanes'
 * results, never a different formula. Built with -ffp-contract=off like mcu_law.c. Host
 * only: the Cortex-M4 image does not link it.
 */
#ifndef MCU_LAW_LANES_H
#define MCU_LAW_LANES_H

#include "mcu_law.h"

/* Lanes per batch: the engine's batch width (plant.lanes.LW). */
#define MCU_LW 8

/* The program's scalar fields, as in mcu_state: X(type, name). */
#define MCU_LANE_CONFIG(X)                                                                   \
    X(float, adc_lsb_v) X(float, kc) X(float, rad_per_count) X(float, m_per_rad)             \
    X(float, n_per_code) X(float, m_per_count) X(float, rad_per_ssi) X(float, a_per_ma)      \
    X(int32_t, strain_mid) X(int32_t, biss_zero) X(float, dt) X(float, kt_eq) X(float, kp)   \
    X(float, kd) X(float, derivative_a) X(float, observer_j) X(float, observer_ko)           \
    X(float, bemf) X(float, vel_kp) X(float, vel_ki) X(float, force_kp) X(float, force_ki)   \
    X(float, highpass_a) X(float, seal_a) X(float, k_pos) X(float, cos_alpha)                \
    X(float, f_lim) X(float, p_lim) X(float, i_lim) X(float, vq_ff_max)                      \
    X(uint32_t, velocity_based) X(uint32_t, feedback) X(int32_t, timeout_ticks)              \
    X(int32_t, off_ticks)

#define MCU_LANE_STATE(X)                                                                    \
    X(float, kp) X(float, k_pos) X(float, f_pres) X(float, tau_q) X(float, f_strain_raw)     \
    X(float, omega_m) X(float, v_pump) X(float, x_piston) X(float, iq) X(float, theta_rotor) \
    X(uint32_t, strain_samples) X(uint32_t, board_status) X(float, lp_seal_y) X(float, hp_y) \
    X(float, hp_u_prev) X(int, hp_started) X(float, d_y) X(float, d_u_prev)                  \
    X(float, force_integral) X(float, velocity_integral) X(float, obs_total)                 \
    X(float, obs_p0) X(float, obs_r) X(int, obs_started) X(float, f_strain) X(float, tau_p)  \
    X(float, tau_used) X(float, f_fb) X(float, f_fil) X(int, i_limited) X(uint32_t, limits)  \
    X(uint32_t, mode) X(float, value) X(int32_t, last_cmd_tick) X(uint32_t, seq)              \
    X(uint32_t, crc_seen_down) X(uint32_t, crc_seen_up) X(float, tau_ref) X(float, i_ref)    \
    X(float, v_ff) X(uint32_t, status)

/* One value per lane: GCC's vector types (elementwise arithmetic, comparisons giving
 * 0 / -1 masks, per-lane access as v[j]), 4-byte aligned so that any buffer will do. On
 * x86-64 without AVX a vector of eight floats is two SSE registers. */
#define MCU_LANE_VECTOR(type) \
    typedef type vec_##type __attribute__((vector_size(sizeof(type) * MCU_LW), aligned(4)))
MCU_LANE_VECTOR(float);
MCU_LANE_VECTOR(double);
MCU_LANE_VECTOR(int32_t);
MCU_LANE_VECTOR(uint32_t);
typedef vec_int32_t vec_int;

#define MCU_LANE_FIELD(type, name) vec_##type name;

typedef struct {
    /* the configurations (read only here: the engine's tunables write the records) */
    struct {
        MCU_LANE_CONFIG(MCU_LANE_FIELD)
        vec_uint32_t analog_register[N_ANALOG];
        vec_float analog_v0[N_ANALOG];
        vec_float analog_mul[N_ANALOG];
        vec_float analog_div[N_ANALOG];
    } cfg;
    /* the states */
    MCU_LANE_STATE(MCU_LANE_FIELD)
    vec_float analog[N_ANALOG];
    vec_uint32_t down[DOWN_WORDS]; /* (16-bit words in 32-bit lanes, like every other) */
    /* this step's input records, gathered into lanes (the upstream words as int32: exact,
     * and what x86 converts to float in vectors) */
    struct {
        vec_int32_t tick;
        vec_uint32_t flags;
        vec_uint32_t mode;
        vec_float value;
        vec_float kp_position;
        vec_float kp_force;
        vec_uint32_t up_crc_errors;
        vec_uint32_t angle_offset;
        vec_int32_t analog_word[N_ANALOG];
        vec_int32_t status, ssi, speed, piston_lo, piston_hi, iq, strain_lo, strain_hi;
        vec_int32_t err_link_crc;
    } in;
} mcu_lanes;

/* sizeof mcu_lanes (the engine allocates one per compute thread). */
uint32_t mcu_lanes_size(void);
/* Lanes 0..m-1 from the programs states[rows[j]]; the free lanes m.. repeat lane m-1 (they
 * compute, and are never stored). */
void mcu_lanes_load(mcu_lanes *lanes, const mcu_state *states, const int64_t *rows, uint32_t m);
/* One step of every lane with the input records in[rows[j]] (mcu_law_step's); the
 * downstream words of lanes 0..m-1 into out[rows[j]].down (the rest of the output record is
 * written by mcu_lanes_store). */
void mcu_lanes_step(mcu_lanes *lanes, const mcu_input *in, mcu_output *out, const int64_t *rows,
                    uint32_t m);
/* Which build of the step runs: 1 the AVX2 one, 0 the one for any x86-64 (the CPU's best
 * at load). avx2 = 0 or 1 selects that build (1 only where the CPU has AVX2; for tests: the
 * choice is the library's, for every thread); any other value only asks. */
int32_t mcu_lanes_build(int32_t avx2);
/* Lanes 0..m-1 back into states[rows[j]] (the configuration is left as it is) and their
 * output records out[rows[j]] in full, as mcu_law_step leaves them. */
void mcu_lanes_store(const mcu_lanes *lanes, mcu_state *states, mcu_output *out,
                     const int64_t *rows, uint32_t m);

#endif
