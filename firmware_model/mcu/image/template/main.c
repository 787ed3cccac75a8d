/* A minimal eha-hil firmware image: force control of one actuator from its cylinder
 * pressures, a P + D law with feed-forward, the command watchdog, and the board's enable
 * sequence. Copy this folder, change the law, `make`, then run it in the loop:
 *     eha-hil run f5 --mcu-image firmware.elf
 * Everything it knows about the actuator comes from the calibration block. */
#include <stdint.h>

#include "eha_hil.h"

#define STATUS_CMD_TIMEOUT 0x001u /* the PC's command is older than timeout_ticks */
#define STATUS_SAFE_OFF 0x002u    /* ... than off_ticks: the board is switched off */

static const eha_cal *cal;
static uint32_t mode, seq;
static float value, d_y, f_prev;
static int32_t last_cmd_tick;

static float clamp(float x, float lim)
{
    return x > lim ? lim : (x < -lim ? -lim : x);
}

/* An analog input in SI units (Pa for the pressures). */
static float analog(int k)
{
    float volts = (float)EHA_UP(0)[cal->analog_register[k]] * cal->adc_lsb_v;
    return (volts - cal->analog_v0[k]) * cal->analog_mul[k] / cal->analog_div[k];
}

int main(void)
{
    if (EHA_CAL->magic != EHA_CAL_MAGIC || EHA_CAL->size < sizeof(eha_cal))
        __builtin_trap(); /* no calibration: the harness reports a hard fault at boot */
    cal = EHA_CAL_RECORD;
    for (int k = 0; k < 16; k++)
        EHA_DOWN(0)[k] = cal->down_init[k];
    return 0; /* the reset handler then waits for interrupts */
}

void TIM2_IRQHandler(void)
{
    volatile uint16_t *down = EHA_DOWN(0);
    volatile const uint16_t *up = EHA_UP(0);
    uint32_t flags = EHA_RX->flags;
    if (flags & EHA_RX_CLEAR_FAULT)
        down[EHA_D_CONTROL] = EHA_CTRL_CLEAR_FAULT;
    if (flags & EHA_RX_ENABLE) {
        down[EHA_D_ANGLE_OFFSET] = (uint16_t)EHA_RX->angle_offset;
        down[EHA_D_MODE] = EHA_BOARD_MODE_CURRENT;
        down[EHA_D_CONTROL] = EHA_CTRL_ENABLE;
        d_y = 0.0f;
    } else if (flags & EHA_RX_DISABLE) {
        down[EHA_D_CONTROL] = 0;
    }
    if (flags & EHA_RX_COMMAND) {
        mode = EHA_RX->mode;
        value = EHA_RX->value;
        last_cmd_tick = EHA_RX->tick;
    }
    /* measurements: piston force from the cylinder chambers (inputs 3 and 4) */
    float f = cal->kc * (analog(3) - analog(4));
    int32_t count = (int32_t)(((uint32_t)up[EHA_U_PISTON_HI] << 16) | up[EHA_U_PISTON_LO]);
    float x = (float)(count - cal->biss_zero) * cal->m_per_count;
    /* the force reference, or zero when the PC has gone quiet */
    uint32_t status = 0;
    int32_t age = EHA_RX->tick - last_cmd_tick;
    float tau_ref = 0.0f;
    if (mode != EHA_MODE_OFF && age > cal->timeout_ticks) {
        status |= STATUS_CMD_TIMEOUT;
        if (age > cal->off_ticks) {
            status |= STATUS_SAFE_OFF;
            down[EHA_D_CONTROL] = 0;
        }
    } else if (mode == EHA_MODE_FORCE) {
        tau_ref = value;
    } else if (mode == EHA_MODE_POSITION) {
        tau_ref = cal->k_pos * (value - x);
    }
    tau_ref = clamp(tau_ref, cal->f_lim);
    /* P + D on the force error, with the reference fed forward */
    d_y += cal->derivative_a * ((f - f_prev) / cal->dt - d_y);
    f_prev = f;
    float tau = tau_ref + cal->kp * (tau_ref - f) - cal->kd * d_y;
    float i_ref = mode == EHA_MODE_OFF ? 0.0f : clamp(tau / cal->kt_eq, cal->i_lim);
    float ma = i_ref * 1000.0f;
    down[EHA_D_IQ_REF] = (uint16_t)(int16_t)(ma + (ma >= 0.0f ? 0.5f : -0.5f));
    down[EHA_D_VQ_FF] = 0;
    down[EHA_D_SEQUENCE] = (uint16_t)++seq;
    /* process data to the PC: what the harness logs */
    EHA_TX->status = status;
    EHA_TX->tau_ref = tau_ref;
    EHA_TX->i_ref = i_ref;
    EHA_TX->f_pres = f;
    EHA_TX->f_fb = f;
    EHA_TX->f_fil = f;
    EHA_TX->x_piston = x;
}
