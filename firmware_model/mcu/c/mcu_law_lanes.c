/* The MCU law in lanes (see mcu_law_lanes.h): mcu_law.c's process_data, measure, cycle and
 * controller_step on vectors of MCU_LW actuators.
 *
 * How a branch of the scalar law becomes lane code without changing any lane's result:
 * both sides are computed in every lane and a select (bitwise, on the mask of the scalar
 * law's condition) keeps, per lane, the side the scalar law takes; a state the scalar law
 * leaves alone keeps its old value. Every float expression is the scalar one, operand for
 * operand and in its order (the comments give the scalar line where the form differs);
 * vector adds, multiplies, divides, compares and int <-> float conversions round as their
 * scalar forms do (IEEE 754, round to nearest even, no contraction: -ffp-contract=off).
 * A free lane (past the batch's size) repeats the batch's last actuator and is never
 * stored. Only the gathers and scatters of the records are lane by lane (transposes).
 */
#include "mcu_law_lanes.h"

#include <stddef.h>

/* Vectors pass by value only between this file's static functions (no ABI to keep). */
#pragma GCC diagnostic ignored "-Wpsabi"

/* Every helper is inlined into the step's two builds (below), with their instructions. */
#define INLINE inline __attribute__((always_inline))

typedef vec_int32_t mask; /* per lane: -1 (true) or 0 */
static const vec_uint32_t ZU = {0};
static const vec_int32_t ZI = {0};
static const vec_float ZF = {0};

uint32_t mcu_lanes_size(void)
{
    return (uint32_t)sizeof(mcu_lanes);
}

/* Vectors are built from the eight lanes' values in registers and stored whole: a vector
 * load right after eight 4-byte stores to its bytes would wait for them to reach the cache
 * (no store forwarding), once per vector. */
typedef char mcu_lw_is_eight[MCU_LW == 8 ? 1 : -1];
#define ON8(p, member) \
    {p[0]->member, p[1]->member, p[2]->member, p[3]->member, \
     p[4]->member, p[5]->member, p[6]->member, p[7]->member}

/* The records of lanes 0..m-1 at base[rows[j]]; a free lane repeats the batch's last. */
#define LANE_RECORDS(p, base, rows, m)                    \
    for (uint32_t j_ = 0; j_ < MCU_LW; j_++)                \
        p[j_] = &(base)[(rows)[j_ < (m) ? j_ : (m) - 1]]

static INLINE void load(mcu_lanes *restrict L, const mcu_state *states, const int64_t *rows,
                        uint32_t m)
{
    const mcu_state *s[MCU_LW];
    LANE_RECORDS(s, states, rows, m);
#define LOAD_CFG(type, name) L->cfg.name = (vec_##type)ON8(s, cfg.name);
#define LOAD(type, name) L->name = (vec_##type)ON8(s, name);
    MCU_LANE_CONFIG(LOAD_CFG)
    MCU_LANE_STATE(LOAD)
    for (int k = 0; k < N_ANALOG; k++) {
        L->cfg.analog_register[k] = (vec_uint32_t)ON8(s, cfg.analog_register[k]);
        L->cfg.analog_v0[k] = (vec_float)ON8(s, cfg.analog_v0[k]);
        L->cfg.analog_mul[k] = (vec_float)ON8(s, cfg.analog_mul[k]);
        L->cfg.analog_div[k] = (vec_float)ON8(s, cfg.analog_div[k]);
        L->analog[k] = (vec_float)ON8(s, analog[k]);
    }
    for (int w = 0; w < DOWN_WORDS; w++)
        L->down[w] = (vec_uint32_t)ON8(s, down[w]);
}

static INLINE void store(const mcu_lanes *restrict L, mcu_state *states, mcu_output *out,
                         const int64_t *rows, uint32_t m)
{
    for (uint32_t j = 0; j < m; j++) {
        mcu_state *s = &states[rows[j]];
#define STORE(type, name) s->name = L->name[j];
        MCU_LANE_STATE(STORE)
        for (int k = 0; k < N_ANALOG; k++)
            s->analog[k] = L->analog[k][j];
        for (int w = 0; w < DOWN_WORDS; w++)
            s->down[w] = (uint16_t)L->down[w][j];
        mcu_law_report(s, &out[rows[j]]);
    }
}

/* The input records of the batch's lanes: what mcu_law_step reads of them. */
static INLINE void gather(mcu_lanes *restrict L, const mcu_input *in, const int64_t *rows,
                          uint32_t m)
{
    const mcu_input *p[MCU_LW];
    LANE_RECORDS(p, in, rows, m);
    L->in.tick = (vec_int32_t)ON8(p, tick);
    L->in.flags = (vec_uint32_t)ON8(p, flags);
    L->in.mode = (vec_uint32_t)ON8(p, mode);
    L->in.value = (vec_float)ON8(p, value);
    L->in.kp_position = (vec_float)ON8(p, kp_position);
    L->in.kp_force = (vec_float)ON8(p, kp_force);
    L->in.up_crc_errors = (vec_uint32_t)ON8(p, up_crc_errors);
    L->in.angle_offset = (vec_uint32_t)ON8(p, angle_offset);
    for (int k = 0; k < N_ANALOG; k++) {
        vec_uint32_t r = L->cfg.analog_register[k]; /* each lane's own register */
        L->in.analog_word[k] = (vec_int32_t){p[0]->up[r[0]], p[1]->up[r[1]], p[2]->up[r[2]],
                                             p[3]->up[r[3]], p[4]->up[r[4]], p[5]->up[r[5]],
                                             p[6]->up[r[6]], p[7]->up[r[7]]};
    }
    L->in.status = (vec_int32_t)ON8(p, up[U_STATUS]);
    L->in.ssi = (vec_int32_t)ON8(p, up[U_SSI]);
    L->in.speed = (vec_int32_t)ON8(p, up[U_SPEED]);
    L->in.piston_lo = (vec_int32_t)ON8(p, up[U_PISTON_LO]);
    L->in.piston_hi = (vec_int32_t)ON8(p, up[U_PISTON_HI]);
    L->in.iq = (vec_int32_t)ON8(p, up[U_IQ]);
    L->in.strain_lo = (vec_int32_t)ON8(p, up[U_STRAIN_LO]);
    L->in.strain_hi = (vec_int32_t)ON8(p, up[U_STRAIN_HI]);
    L->in.err_link_crc = (vec_int32_t)ON8(p, up[U_ERR_LINK_CRC]);
}

static INLINE vec_float fsel(mask m, vec_float a, vec_float b)
{
    return (vec_float)((m & (mask)a) | (~m & (mask)b));
}

static INLINE vec_uint32_t usel(mask m, vec_uint32_t a, vec_uint32_t b)
{
    return ((vec_uint32_t)m & a) | (~(vec_uint32_t)m & b);
}

static INLINE vec_int32_t isel(mask m, vec_int32_t a, vec_int32_t b)
{
    return (m & a) | (~m & b);
}

/* b where m, else 0 (a status bit or flag) */
static INLINE vec_uint32_t bits(mask m, uint32_t b)
{
    return (vec_uint32_t)m & b;
}

static INLINE vec_float to_float(vec_int32_t x)
{
    return __builtin_convertvector(x, vec_float);
}

/* clampf: lim where x > lim, else -lim where x < -lim, else x. */
static INLINE vec_float clamp(vec_float x, vec_float lim)
{
    return fsel(x > lim, lim, fsel(x < -lim, -lim, x));
}

/* round_half_even (x + 1.5 * 2^23 - 1.5 * 2^23, truncated), then the cast to a 16-bit word */
static INLINE vec_uint32_t word(vec_float x)
{
    const float magic = 12582912.0f;
    vec_float r = (x + magic) - magic;
    return (vec_uint32_t)__builtin_convertvector(r, vec_int32_t) & 0xFFFFu;
}

/* s16 of a 16-bit word held in an int32: w - 0x10000 where bit 15 is set. */
static INLINE vec_int32_t s16(vec_int32_t w)
{
    return w - ((w & 0x8000) << 1);
}

/* controller_reset where r: every controller state back to zero. */
static INLINE void reset(mcu_lanes *L, mask r)
{
    L->d_y = fsel(r, ZF, L->d_y);
    L->d_u_prev = fsel(r, ZF, L->d_u_prev);
    L->obs_total = fsel(r, ZF, L->obs_total);
    L->obs_p0 = fsel(r, ZF, L->obs_p0);
    L->obs_started = isel(r, ZI, L->obs_started);
    L->obs_r = fsel(r, ZF, L->obs_r);
    L->velocity_integral = fsel(r, ZF, L->velocity_integral);
    L->force_integral = fsel(r, ZF, L->force_integral);
    L->hp_y = fsel(r, ZF, L->hp_y);
    L->hp_u_prev = fsel(r, ZF, L->hp_u_prev);
    L->hp_started = isel(r, ZI, L->hp_started);
    L->lp_seal_y = fsel(r, ZF, L->lp_seal_y);
    L->f_strain = fsel(r, ZF, L->f_strain);
    L->i_limited = isel(r, ZI, L->i_limited);
    L->tau_p = fsel(r, ZF, L->tau_p);
    L->tau_used = fsel(r, ZF, L->tau_used);
    L->f_fb = fsel(r, ZF, L->f_fb);
    L->f_fil = fsel(r, ZF, L->f_fil);
    L->limits = usel(r, ZU, L->limits);
}

/* process_data: the cycle's edges, gains and command. */
static INLINE void process(mcu_lanes *L)
{
    vec_uint32_t f = L->in.flags;
    mask clear = (f & IN_CLEAR_FAULT) != 0;
    mask enable = (f & IN_ENABLE) != 0;
    mask disable = ~enable & ((f & IN_DISABLE) != 0);
    vec_uint32_t control = usel(clear, ZU + CTRL_CLEAR_FAULT,
                                L->down[D_CONTROL]);
    control = usel(enable, ZU + CTRL_ENABLE, control);
    L->down[D_CONTROL] = usel(disable, ZU, control);
    L->down[D_ANGLE_OFFSET] = usel(enable, L->in.angle_offset & 0xFFFFu,
                                   L->down[D_ANGLE_OFFSET]);
    L->down[D_MODE] = usel(enable, ZU + BOARD_MODE_CURRENT, L->down[D_MODE]);
    reset(L, enable);
    mask gains = (f & IN_GAINS) != 0;
    vec_float k_pos = fsel(L->in.kp_position > 0.0f, L->in.kp_position, L->cfg.k_pos);
    vec_float kp = fsel(L->in.kp_force > 0.0f, L->in.kp_force, L->cfg.kp);
    L->k_pos = fsel(gains, k_pos, L->k_pos);
    L->kp = fsel(gains, kp, L->kp);
    mask command = (f & IN_COMMAND) != 0;
    L->mode = usel(command, L->in.mode, L->mode);
    L->value = fsel(command, L->in.value, L->value);
    L->last_cmd_tick = isel(command, L->in.tick, L->last_cmd_tick);
}

/* measure: the upstream words in SI units. */
static INLINE void measure(mcu_lanes *L)
{
    for (int k = 0; k < N_ANALOG; k++) {
        vec_float volts = to_float(L->in.analog_word[k]) * L->cfg.adc_lsb_v;
        L->analog[k] = (volts - L->cfg.analog_v0[k]) * L->cfg.analog_mul[k]
                       / L->cfg.analog_div[k];
    }
    L->f_pres = L->cfg.kc * (L->analog[A_P_CYL_A] - L->analog[A_P_CYL_B]);
    L->tau_q = L->cfg.kc * (L->analog[A_P_PUMP_A] - L->analog[A_P_PUMP_B]);
    vec_int32_t hi = L->in.strain_hi;
    vec_int32_t code = ((hi & 0xFF) << 16) | L->in.strain_lo;
    L->strain_samples = (vec_uint32_t)(hi >> 8);
    L->f_strain_raw = to_float(code - L->cfg.strain_mid) * L->cfg.n_per_code;
    L->omega_m = to_float(s16(L->in.speed)) * L->cfg.rad_per_count;
    L->v_pump = L->omega_m * L->cfg.m_per_rad;
    /* scalar: (float)(int64 count - biss_zero). Every term is an integer below 2^53, so the
     * double is that difference exactly and the cast rounds it once, as the int64
     * conversion does; x86 converts int32 -> double in vectors, not int64 -> float. */
    vec_double count = __builtin_convertvector(L->in.piston_hi, vec_double) * 65536.0
                       + __builtin_convertvector(L->in.piston_lo, vec_double);
    vec_double x = count - __builtin_convertvector(L->cfg.biss_zero, vec_double);
    L->x_piston = __builtin_convertvector(x, vec_float) * L->cfg.m_per_count;
    L->iq = to_float(s16(L->in.iq)) * L->cfg.a_per_ma;
    L->theta_rotor = to_float(L->in.ssi) * L->cfg.rad_per_ssi;
    L->board_status = (vec_uint32_t)L->in.status;
}

/* cycle's watchdog and command choice: the force command and the watchdog's status. */
static INLINE vec_float command(mcu_lanes *L, vec_uint32_t *status)
{
    L->seq = (L->seq + 1u) & 0xFFFFu;
    vec_int32_t age = L->in.tick - L->last_cmd_tick;
    vec_uint32_t mode = L->mode;
    mask timeout = (age > L->cfg.timeout_ticks) & (mode != MODE_OFF);
    mask off = timeout & (age > L->cfg.off_ticks);
    vec_float position = L->k_pos * (L->value - L->x_piston);
    vec_float tau = fsel(mode == MODE_POSITION, position, ZF);
    tau = fsel(mode == MODE_FORCE, L->value, tau);
    *status = bits(timeout, CMD_TIMEOUT) | bits(off, SAFE_OFF);
    L->down[D_CONTROL] = usel(off, ZU, L->down[D_CONTROL]);
    return fsel(timeout, ZF, tau);
}

/* controller_step where the mode is not off, controller_reset where it is, with the force
 * command tau_ref: the current reference, feed-forward voltage and force command used. */
static INLINE void controller(mcu_lanes *L, vec_float tau_ref)
{
    mask on = L->mode != MODE_OFF;
    vec_float f_lim = L->cfg.f_lim, p_lim = L->cfg.p_lim;
    vec_uint32_t limits = bits((tau_ref > f_lim) | (tau_ref < -f_lim), FORCE_LIMITED);
    vec_float t = clamp(tau_ref, f_lim);
    mask high = (L->analog[A_P_CYL_A] > p_lim) | (L->analog[A_P_CYL_B] > p_lim)
                | (L->analog[A_P_PUMP_A] > p_lim) | (L->analog[A_P_PUMP_B] > p_lim);
    limits |= bits(high, PRESSURE_HIGH);
    /* feedback_force and its high-pass (first sample: start at rest) */
    vec_float f_pres = L->f_pres;
    mask strain = L->strain_samples != 0;
    vec_uint32_t feedback = L->cfg.feedback;
    vec_float f_strain_new = L->cfg.cos_alpha * L->f_strain_raw;
    vec_float u = f_strain_new - f_pres;
    vec_float u_prev = fsel(L->hp_started != 0, L->hp_u_prev, u);
    vec_float hp_y = fsel(strain, L->cfg.highpass_a * (L->hp_y + u - u_prev), L->hp_y);
    vec_float hp_u_prev = fsel(strain, u, L->hp_u_prev);
    vec_int32_t hp_started = isel(strain, ZI + 1, L->hp_started);
    vec_float f_fil = fsel(strain, f_pres + hp_y, f_pres);
    vec_float f_strain = fsel(strain & (feedback != FB_PRESSURE), f_strain_new, L->f_strain);
    vec_float f = fsel(strain & (feedback == FB_COMPLEMENTARY), f_fil, f_pres);
    /* the seal friction's low-pass (lowpass: y += a * (u - y)) */
    mask seal_on = (feedback == FB_STRAIN) & strain & (L->i_limited == 0);
    vec_float seal = L->lp_seal_y;
    seal = fsel(seal_on, seal + L->cfg.seal_a * ((f_pres - f_strain) - seal), seal);
    vec_float e = t + seal - f;
    /* velocity-based: velocity_pi(force_pi(e) - v_pump) */
    mask velocity = L->cfg.velocity_based != 0;
    vec_float v_pump = L->v_pump;
    vec_float force_pi = L->cfg.force_kp * e + L->force_integral;
    vec_float tau_v = L->cfg.vel_kp * (force_pi - v_pump) + L->velocity_integral;
    /* current-based: derivative(f) (d_y += a * ((u - u_prev) / dt - d_y)), then the law */
    vec_float dt = L->cfg.dt;
    vec_float d_y = L->d_y + L->cfg.derivative_a * ((f - L->d_u_prev) / dt - L->d_y);
    vec_float tau_c = t + seal + L->kp * e - L->cfg.kd * d_y - L->obs_r;
    vec_float kt_eq = L->cfg.kt_eq, i_lim = L->cfg.i_lim;
    vec_float i_ref = fsel(velocity, tau_v, tau_c) / kt_eq;
    mask saturated = (i_ref > i_lim) | (i_ref < -i_lim);
    limits |= bits(saturated, CURRENT_LIMITED);
    i_ref = clamp(i_ref, i_lim);
    /* velocity-based, not saturated (no wind-up): force_integral += ki * e * dt, then
     * velocity_integral += ki * (force_pi(e) - v_pump) * dt with the new integral */
    mask wind = velocity & ~saturated;
    vec_float fi = L->force_integral + L->cfg.force_ki * e * dt;
    vec_float vi = L->velocity_integral
                   + L->cfg.vel_ki * (L->cfg.force_kp * e + fi - v_pump) * dt;
    fi = fsel(wind, fi, L->force_integral);
    vi = fsel(wind, vi, L->velocity_integral);
    /* current-based: observer(v_pump, kt_eq * iq, tau_q) (first step: p0 = momentum) */
    vec_float momentum = L->cfg.observer_j * v_pump;
    vec_float p0 = fsel(L->obs_started != 0, L->obs_p0, momentum);
    vec_float total = L->obs_total + (kt_eq * L->iq - L->tau_q + L->obs_r) * dt;
    vec_float r = L->cfg.observer_ko * (momentum - p0 - total);
    vec_float v_ff = clamp(L->cfg.bemf * L->omega_m, L->cfg.vq_ff_max);
    /* commit: the step's values where on, controller_reset's zeros where off */
    L->limits = usel(on, limits, ZU);
    L->tau_used = fsel(on, t, ZF);
    L->hp_y = fsel(on, hp_y, ZF);
    L->hp_u_prev = fsel(on, hp_u_prev, ZF);
    L->hp_started = isel(on, hp_started, ZI);
    L->f_fil = fsel(on, f_fil, ZF);
    L->f_strain = fsel(on, f_strain, ZF);
    L->f_fb = fsel(on, f, ZF);
    L->lp_seal_y = fsel(on, seal, ZF);
    L->d_y = fsel(on, fsel(velocity, L->d_y, d_y), ZF);
    L->d_u_prev = fsel(on, fsel(velocity, L->d_u_prev, f), ZF);
    L->i_limited = isel(on, saturated & 1, ZI);
    L->force_integral = fsel(on, fi, ZF);
    L->velocity_integral = fsel(on, vi, ZF);
    L->obs_p0 = fsel(on, fsel(velocity, L->obs_p0, p0), ZF);
    L->obs_started = isel(on, isel(velocity, L->obs_started, ZI + 1), ZI);
    L->obs_total = fsel(on, fsel(velocity, L->obs_total, total), ZF);
    L->obs_r = fsel(on, fsel(velocity, L->obs_r, r), ZF);
    L->tau_p = fsel(on, i_ref * kt_eq, ZF);
    L->tau_ref = fsel(on, t, tau_ref);
    L->i_ref = fsel(on, i_ref, ZF);
    L->v_ff = fsel(on, v_ff, ZF);
}

/* The rest of cycle: the downstream words and the status word. */
static INLINE void report(mcu_lanes *L, vec_uint32_t watchdog)
{
    L->down[D_IQ_REF] = word(L->i_ref * 1000.0f);
    L->down[D_VQ_FF] = word(L->v_ff * 1000.0f);
    L->down[D_SEQUENCE] = L->seq;
    vec_uint32_t board = L->board_status;
    vec_uint32_t status = watchdog | L->limits;
    status |= bits((board & ST_FAULT) != 0, BOARD_FAULT);
    status |= bits((board & ST_ENABLED) != 0, BOARD_ENABLED);
    status |= bits((board & ST_ENCODER_ERROR) != 0, ENCODER_ERROR);
    status |= bits((board & ST_STRAIN_ERROR) != 0, STRAIN_ERROR);
    vec_uint32_t crc_down = (vec_uint32_t)L->in.err_link_crc, crc_up = L->in.up_crc_errors;
    mask link = ((board & ST_LINK_LOST) != 0) | (crc_down != L->crc_seen_down)
                | (crc_up != L->crc_seen_up) | (crc_down == CRC_COUNT_MAX);
    L->status = status | bits(link, LINK_ERROR);
    L->crc_seen_down = crc_down;
    L->crc_seen_up = crc_up;
}

static INLINE void step(mcu_lanes *restrict L, const mcu_input *in, mcu_output *out,
                       const int64_t *rows, uint32_t m)
{
    vec_uint32_t watchdog;
    gather(L, in, rows, m);
    process(L);
    measure(L);
    controller(L, command(L, &watchdog));
    report(L, watchdog);
    for (uint32_t j = 0; j < m; j++)
        for (int w = 0; w < DOWN_WORDS; w++)
            out[rows[j]].down[w] = (uint16_t)L->down[w][j];
}

/* Two builds of each entry point: with AVX2 (one 256-bit register per vector) and for any
 * x86-64 (SSE2: pairs of 128-bit registers, some compares lane by lane). Both round every
 * operation alike (no FMA in either: AVX2 does not imply it, and contraction is off), so
 * they give the same bits; a CPU check when the library loads picks one. */
#define TWO_BUILDS(name, params, args)                                                      \
    __attribute__((target("avx2"))) static void name##_avx2 params { name args; }          \
    static void name##_generic params { name args; }

TWO_BUILDS(load, (mcu_lanes *restrict L, const mcu_state *s, const int64_t *rows, uint32_t m),
           (L, s, rows, m))
TWO_BUILDS(step, (mcu_lanes *restrict L, const mcu_input *in, mcu_output *out,
                  const int64_t *rows, uint32_t m), (L, in, out, rows, m))
TWO_BUILDS(store, (const mcu_lanes *restrict L, mcu_state *s, mcu_output *out,
                   const int64_t *rows, uint32_t m), (L, s, out, rows, m))

static int use_avx2;

__attribute__((constructor)) static void pick_build(void)
{
    __builtin_cpu_init();
    use_avx2 = __builtin_cpu_supports("avx2");
}

int32_t mcu_lanes_build(int32_t avx2)
{
    if (avx2 == 0 || (avx2 == 1 && __builtin_cpu_supports("avx2")))
        use_avx2 = avx2;
    return use_avx2;
}

void mcu_lanes_load(mcu_lanes *restrict L, const mcu_state *states, const int64_t *rows,
                    uint32_t m)
{
    if (m == 0)
        return;
    (use_avx2 ? load_avx2 : load_generic)(L, states, rows, m);
}

void mcu_lanes_step(mcu_lanes *restrict L, const mcu_input *in, mcu_output *out,
                    const int64_t *rows, uint32_t m)
{
    if (m == 0)
        return;
    (use_avx2 ? step_avx2 : step_generic)(L, in, out, rows, m);
}

void mcu_lanes_store(const mcu_lanes *restrict L, mcu_state *states, mcu_output *out,
                     const int64_t *rows, uint32_t m)
{
    (use_avx2 ? store_avx2 : store_generic)(L, states, out, rows, m);
}
