/* The MCU law on the netduinoplus2 (STM32F405) under QEMU: reads "mcu_in.bin" (header,
 * mcu_config, n mcu_input records) through semihosting, runs the law, writes n mcu_output
 * records to "mcu_out.bin". The header carries the record sizes, so a layout that drifted
 * from the host's is refused rather than misread. */
#include <stdio.h>
#include <stdlib.h>

#include "../mcu_law.h"

extern void initialise_monitor_handles(void);

#define MAGIC 0x4C55434Du /* "MCUL" */

static mcu_state state;
static mcu_config config;
static char in_buf[4096], out_buf[4096];

static void fail(const char *what)
{
    fprintf(stderr, "mcu image: %s\n", what);
    exit(2);
}

int main(void)
{
    initialise_monitor_handles();
    FILE *in = fopen("mcu_in.bin", "rb");
    FILE *out = fopen("mcu_out.bin", "wb");
    if (!in || !out)
        fail("cannot open mcu_in.bin / mcu_out.bin");
    setvbuf(in, in_buf, _IOFBF, sizeof in_buf);
    setvbuf(out, out_buf, _IOFBF, sizeof out_buf);
    uint32_t head[5];
    if (fread(head, sizeof head, 1, in) != 1 || head[0] != MAGIC)
        fail("mcu_in.bin: no MCUL header");
    if (head[1] != sizeof(mcu_config) || head[2] != sizeof(mcu_input)
        || head[3] != sizeof(mcu_output))
        fail("mcu_in.bin: record sizes differ from this image's");
    if (fread(&config, sizeof config, 1, in) != 1)
        fail("mcu_in.bin: short configuration");
    mcu_law_init(&state, &config);
    mcu_input rec;
    mcu_output res;
    for (uint32_t k = 0; k < head[4]; k++) {
        if (fread(&rec, sizeof rec, 1, in) != 1)
            fail("mcu_in.bin: short input");
        mcu_law_step(&state, &rec, &res);
        if (fwrite(&res, sizeof res, 1, out) != 1)
            fail("mcu_out.bin: write failed");
    }
    if (fclose(out) != 0)
        fail("mcu_out.bin: close failed");
    fclose(in);
    exit(0);
}
