/* The MCU's force-control law for one actuator (see mcu_law.h). Float32 only: every
 * constant is a float literal or comes from mcu_config; no libm call. */
#include "mcu_law.h"

#include <string.h>

static float clampf(float x, float lim)
{
    if (x > lim)
        return lim;
    if (x < -lim)
        return -lim;
    return x;
}

/* Round half to even, for |x| < 2^22: adding 1.5 * 2^23 lands in [2^23, 2^24), where the
 * float32 spacing is 1, so the FPU's round-to-nearest-even does the rounding. */
static int32_t round_half_even(float x)
{
    const float magic = 12582912.0f;
    return (int32_t)((x + magic) - magic);
}

static int32_t s16(uint16_t w)
{
    return (int32_t)w - ((w & 0x8000u) ? 0x10000 : 0);
}

/* --- measure.py: Measurements.update ------------------------------------------------ */
static void measure(mcu_state *s, const uint16_t *up)
{
    const mcu_config *c = &s->cfg;
    for (int k = 0; k < N_ANALOG; k++) {
        float volts = (float)up[c->analog_register[k]] * c->adc_lsb_v;
        s->analog[k] = (volts - c->analog_v0[k]) * c->analog_mul[k] / c->analog_div[k];
    }
    s->f_pres = c->kc * (s->analog[A_P_CYL_A] - s->analog[A_P_CYL_B]);
    s->tau_q = c->kc * (s->analog[A_P_PUMP_A] - s->analog[A_P_PUMP_B]);
    uint32_t hi = up[U_STRAIN_HI];
    int32_t code = (int32_t)(((hi & 0xFFu) << 16) | up[U_STRAIN_LO]);
    s->strain_samples = hi >> 8;
    s->f_strain_raw = (float)(code - c->strain_mid) * c->n_per_code;
    s->omega_m = (float)s16(up[U_SPEED]) * c->rad_per_count;
    s->v_pump = s->omega_m * c->m_per_rad;
    int64_t count = (int64_t)(((uint32_t)up[U_PISTON_HI] << 16) | up[U_PISTON_LO]);
    s->x_piston = (float)(count - c->biss_zero) * c->m_per_count;
    s->iq = (float)s16(up[U_IQ]) * c->a_per_ma;
    s->theta_rotor = (float)up[U_SSI] * c->rad_per_ssi;
    s->board_status = up[U_STATUS];
}

/* --- filters.py ---------------------------------------------------------------------- */
static float lowpass(float *y, float a, float u)
{
    *y += a * (u - *y);
    return *y;
}

static float highpass(mcu_state *s, float u)
{
    if (!s->hp_started) { /* first sample: start at rest */
        s->hp_u_prev = u;
        s->hp_started = 1;
    }
    s->hp_y = s->cfg.highpass_a * (s->hp_y + u - s->hp_u_prev);
    s->hp_u_prev = u;
    return s->hp_y;
}

static float derivative(mcu_state *s, float u)
{
    s->d_y += s->cfg.derivative_a * ((u - s->d_u_prev) / s->cfg.dt - s->d_y);
    s->d_u_prev = u;
    return s->d_y;
}

static float observer(mcu_state *s, float v, float tau_in, float tau_out)
{
    float momentum = s->cfg.observer_j * v;
    if (!s->obs_started) {
        s->obs_p0 = momentum;
        s->obs_started = 1;
    }
    s->obs_total += (tau_in - tau_out + s->obs_r) * s->cfg.dt;
    s->obs_r = s->cfg.observer_ko * (momentum - s->obs_p0 - s->obs_total);
    return s->obs_r;
}

static float force_pi(const mcu_state *s, float e)
{
    return s->cfg.force_kp * e + s->force_integral;
}

static float velocity_pi(const mcu_state *s, float e)
{
    return s->cfg.vel_kp * e + s->velocity_integral;
}

/* --- controller.py: ActuatorController ---------------------------------------------- */
static void controller_reset(mcu_state *s)
{
    s->d_y = 0.0f;
    s->d_u_prev = 0.0f;
    s->obs_total = 0.0f;
    s->obs_p0 = 0.0f;
    s->obs_started = 0;
    s->obs_r = 0.0f;
    s->velocity_integral = 0.0f;
    s->force_integral = 0.0f;
    s->hp_y = 0.0f;
    s->hp_u_prev = 0.0f;
    s->hp_started = 0;
    s->lp_seal_y = 0.0f;
    s->f_strain = 0.0f;
    s->i_limited = 0;
    s->tau_p = 0.0f;
    s->tau_used = 0.0f;
    s->f_fb = 0.0f;
    s->f_fil = 0.0f;
    s->limits = 0;
}

static float feedback_force(mcu_state *s)
{
    if (s->strain_samples == 0) { /* no AD7195 conversion read yet */
        s->f_fil = s->f_pres;
        return s->f_pres;
    }
    float f_strain = s->cfg.cos_alpha * s->f_strain_raw;
    s->f_fil = s->f_pres + highpass(s, f_strain - s->f_pres);
    if (s->cfg.feedback == FB_PRESSURE)
        return s->f_pres;
    s->f_strain = f_strain;
    return s->cfg.feedback == FB_COMPLEMENTARY ? s->f_fil : s->f_pres;
}

static void controller_step(mcu_state *s, float tau_ref, float *i_out, float *v_out)
{
    const mcu_config *c = &s->cfg;
    s->limits = 0;
    if (tau_ref > c->f_lim || tau_ref < -c->f_lim) {
        tau_ref = clampf(tau_ref, c->f_lim);
        s->limits |= FORCE_LIMITED;
    }
    s->tau_used = tau_ref;
    if (s->analog[A_P_CYL_A] > c->p_lim || s->analog[A_P_CYL_B] > c->p_lim
        || s->analog[A_P_PUMP_A] > c->p_lim || s->analog[A_P_PUMP_B] > c->p_lim)
        s->limits |= PRESSURE_HIGH;
    float f = feedback_force(s);
    s->f_fb = f;
    if (c->feedback == FB_STRAIN && s->strain_samples != 0 && !s->i_limited)
        lowpass(&s->lp_seal_y, c->seal_a, s->f_pres - s->f_strain);
    float seal = s->lp_seal_y;
    float e = tau_ref + seal - f;
    float tau_p;
    if (c->velocity_based) {
        tau_p = velocity_pi(s, force_pi(s, e) - s->v_pump);
    } else {
        float d = derivative(s, f);
        tau_p = tau_ref + seal + s->kp * e - c->kd * d - s->obs_r;
    }
    float i_ref = tau_p / c->kt_eq;
    int saturated = i_ref > c->i_lim || i_ref < -c->i_lim;
    s->i_limited = saturated;
    if (saturated) {
        i_ref = clampf(i_ref, c->i_lim);
        s->limits |= CURRENT_LIMITED;
    }
    if (c->velocity_based) {
        if (!saturated) { /* no wind-up */
            s->force_integral += c->force_ki * e * c->dt;
            s->velocity_integral += c->vel_ki * (force_pi(s, e) - s->v_pump) * c->dt;
        }
    } else {
        observer(s, s->v_pump, c->kt_eq * s->iq, s->tau_q);
    }
    s->tau_p = i_ref * c->kt_eq;
    *i_out = i_ref;
    *v_out = clampf(c->bemf * s->omega_m, c->vq_ff_max);
}

/* --- mcu.py: Mcu, and board.py's process data ---------------------------------------- */
void mcu_law_init(mcu_state *s, const mcu_config *cfg)
{
    memset(s, 0, sizeof *s);
    s->cfg = *cfg;
    s->kp = cfg->kp;
    s->k_pos = cfg->k_pos;
    memcpy(s->down, cfg->down_init, sizeof s->down);
    controller_reset(s);
}

static void process_data(mcu_state *s, const mcu_input *in)
{
    uint32_t f = in->flags;
    if (f & IN_CLEAR_FAULT)
        s->down[D_CONTROL] = CTRL_CLEAR_FAULT;
    if (f & IN_ENABLE) {
        s->down[D_ANGLE_OFFSET] = (uint16_t)in->angle_offset;
        s->down[D_MODE] = BOARD_MODE_CURRENT;
        s->down[D_CONTROL] = CTRL_ENABLE;
        controller_reset(s);
    } else if (f & IN_DISABLE) {
        s->down[D_CONTROL] = 0;
    }
    if (f & IN_GAINS) {
        s->k_pos = in->kp_position > 0.0f ? in->kp_position : s->cfg.k_pos;
        s->kp = in->kp_force > 0.0f ? in->kp_force : s->cfg.kp;
    }
    if (f & IN_COMMAND) {
        s->mode = in->mode;
        s->value = in->value;
        s->last_cmd_tick = in->tick;
    }
}

static void cycle(mcu_state *s, const mcu_input *in)
{
    const mcu_config *c = &s->cfg;
    s->seq = (s->seq + 1u) & 0xFFFFu;
    measure(s, in->up);
    int32_t age = in->tick - s->last_cmd_tick;
    uint32_t status = 0;
    float tau_ref;
    if (age > c->timeout_ticks && s->mode != MODE_OFF) {
        status |= CMD_TIMEOUT;
        tau_ref = 0.0f;
        if (age > c->off_ticks) {
            status |= SAFE_OFF;
            s->down[D_CONTROL] = 0;
        }
    } else if (s->mode == MODE_FORCE) {
        tau_ref = s->value;
    } else if (s->mode == MODE_POSITION) {
        tau_ref = s->k_pos * (s->value - s->x_piston);
    } else {
        tau_ref = 0.0f;
    }
    float i_ref, v_ff;
    if (s->mode == MODE_OFF) {
        i_ref = 0.0f;
        v_ff = 0.0f;
        controller_reset(s);
    } else {
        controller_step(s, tau_ref, &i_ref, &v_ff);
        tau_ref = s->tau_used;
    }
    s->tau_ref = tau_ref;
    s->i_ref = i_ref;
    s->v_ff = v_ff;
    s->down[D_IQ_REF] = (uint16_t)round_half_even(i_ref * 1000.0f);
    s->down[D_VQ_FF] = (uint16_t)round_half_even(v_ff * 1000.0f);
    s->down[D_SEQUENCE] = (uint16_t)s->seq;
    status |= s->limits; /* FORCE_LIMITED, CURRENT_LIMITED, PRESSURE_HIGH */
    uint32_t board = s->board_status;
    if (board & ST_FAULT)
        status |= BOARD_FAULT;
    if (board & ST_ENABLED)
        status |= BOARD_ENABLED;
    if (board & ST_ENCODER_ERROR)
        status |= ENCODER_ERROR;
    if (board & ST_STRAIN_ERROR)
        status |= STRAIN_ERROR;
    uint32_t crc_down = in->up[U_ERR_LINK_CRC], crc_up = in->up_crc_errors;
    if ((board & ST_LINK_LOST) || crc_down != s->crc_seen_down || crc_up != s->crc_seen_up
        || crc_down == CRC_COUNT_MAX)
        status |= LINK_ERROR;
    s->crc_seen_down = crc_down;
    s->crc_seen_up = crc_up;
    s->status = status;
}

void mcu_law_report(const mcu_state *s, mcu_output *out)
{
    memcpy(out->down, s->down, sizeof out->down);
    out->status = s->status;
    out->i_ref = s->i_ref;
    out->v_ff = s->v_ff;
    out->tau_ref = s->tau_ref;
    out->tau_p = s->tau_p;
    out->f_fb = s->f_fb;
    out->f_fil = s->f_fil;
    out->f_strain = s->f_strain;
    out->observer_r = s->obs_r;
    out->observer_total = s->obs_total;
    out->derivative_y = s->d_y;
    out->highpass_y = s->hp_y;
    out->seal_y = s->lp_seal_y;
    out->force_integral = s->force_integral;
    out->velocity_integral = s->velocity_integral;
    memcpy(out->m_analog, s->analog, sizeof out->m_analog);
    out->f_pres = s->f_pres;
    out->tau_q = s->tau_q;
    out->f_strain_raw = s->f_strain_raw;
    out->omega_m = s->omega_m;
    out->v_pump = s->v_pump;
    out->x_piston = s->x_piston;
    out->iq = s->iq;
    out->theta_rotor = s->theta_rotor;
}

void mcu_law_step(mcu_state *s, const mcu_input *in, mcu_output *out)
{
    process_data(s, in);
    cycle(s, in);
    mcu_law_report(s, out);
}

void mcu_law_run(const mcu_config *cfg, const mcu_input *in, uint32_t n, mcu_output *out)
{
    static mcu_state s;
    mcu_law_init(&s, cfg);
    for (uint32_t k = 0; k < n; k++)
        mcu_law_step(&s, &in[k], &out[k]);
}

void mcu_law_step_many(mcu_state *s, const mcu_input *in, uint32_t n, mcu_output *out)
{
    for (uint32_t k = 0; k < n; k++)
        mcu_law_step(&s[k], &in[k], &out[k]);
}

uint32_t mcu_law_sizes(uint32_t which)
{
    switch (which) {
    case 0: return (uint32_t)sizeof(mcu_config);
    case 1: return (uint32_t)sizeof(mcu_input);
    case 2: return (uint32_t)sizeof(mcu_output);
    case 3: return (uint32_t)sizeof(mcu_state);
    default: return 0;
    }
}
