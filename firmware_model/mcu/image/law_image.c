/* The project's eha-hil image: the MCU law (firmware_model/mcu/c/mcu_law.c) behind the
 * firmware interface of template/eha_hil.h. main() builds the law's state from the
 * calibration block; the TIM2 handler is one 5 kHz cycle: process data and the DPRAM's
 * upstream words in, the law, downstream words and process data out. */
#include <stddef.h>
#include <string.h>

#include "../c/mcu_law.h"
#include "template/eha_hil.h"

/* The calibration block's record is the law's mcu_config, field by field. */
#define SAME(f) _Static_assert(offsetof(eha_cal, f) == offsetof(mcu_config, f), #f)
SAME(adc_lsb_v); SAME(kc); SAME(rad_per_count); SAME(m_per_rad); SAME(n_per_code);
SAME(m_per_count); SAME(rad_per_ssi); SAME(a_per_ma); SAME(strain_mid); SAME(biss_zero);
SAME(analog_register); SAME(analog_v0); SAME(analog_mul); SAME(analog_div); SAME(dt);
SAME(kt_eq); SAME(kp); SAME(kd); SAME(derivative_a); SAME(observer_j); SAME(observer_ko);
SAME(bemf); SAME(vel_kp); SAME(vel_ki); SAME(force_kp); SAME(force_ki); SAME(highpass_a);
SAME(seal_a); SAME(k_pos); SAME(cos_alpha); SAME(f_lim); SAME(p_lim); SAME(i_lim);
SAME(vq_ff_max); SAME(velocity_based); SAME(feedback); SAME(timeout_ticks);
SAME(off_ticks); SAME(down_init);
_Static_assert(sizeof(eha_cal) == sizeof(mcu_config), "eha_cal size");
/* The process data out is mcu_output from its status field on. */
_Static_assert(sizeof(eha_tx) == sizeof(mcu_output) - offsetof(mcu_output, status), "tx");
_Static_assert(offsetof(eha_tx, theta_rotor) + offsetof(mcu_output, status)
               == offsetof(mcu_output, theta_rotor), "tx fields");

static mcu_state state;
static mcu_input in;
static mcu_output out;

int main(void)
{
    if (EHA_CAL->magic != EHA_CAL_MAGIC || EHA_CAL->size != sizeof(mcu_config))
        __builtin_trap(); /* no calibration for this law: stop at boot */
    mcu_law_init(&state, (const mcu_config *)EHA_CAL_RECORD);
    return 0;
}

void TIM2_IRQHandler(void)
{
    volatile const eha_rx *rx = EHA_RX;
    in.tick = rx->tick;
    in.flags = rx->flags;
    in.mode = rx->mode;
    in.value = rx->value;
    in.kp_position = rx->kp_position;
    in.kp_force = rx->kp_force;
    in.angle_offset = rx->angle_offset;
    in.up_crc_errors = EHA_UP_CRC_ERRORS(0);
    volatile const uint16_t *up = EHA_UP(0);
    for (int k = 0; k < UP_WORDS; k++)
        in.up[k] = up[k];
    mcu_law_step(&state, &in, &out);
    volatile uint16_t *down = EHA_DOWN(0);
    for (int k = 0; k < DOWN_WORDS; k++)
        down[k] = out.down[k];
    memcpy((void *)EHA_TX, &out.status, sizeof(eha_tx));
}
