/* Unicorn hooks for a firmware image in the loop, in C because they run on every basic
 * block and every access to the FSMC bank (a Python callback there costs ~2 us, which would
 * take the image below real time). Unicorn's own functions come in as pointers from the
 * Python binding's library, so this file needs no Unicorn headers.
 *
 * Per block: instructions and estimated cycles from per-halfword prefix sums of the image's
 * code (hil/image/cost.py), a taken-branch penalty when a block does not start where the
 * last one ended, and a stop when the step exceeds its cycle budget. A block whose ends
 * are not instruction boundaries of the table (code outside flash, or data the linear
 * disassembly misread) goes to a pending list that Python prices exactly after the step.
 * Per access: an unaligned address from an instruction that needs alignment stops the
 * run (the Cortex-M4's UNALIGNED UsageFault; Unicorn would carry on). Per FSMC access: the wait states of an external-bus transfer, and the dual-port RAM's
 * access rules (per byte: readable, writable); a violation stops the run with its address,
 * size and PC. */
#include <stddef.h>
#include <stdint.h>

typedef int (*hook_add_fn)(void *uc, size_t *hh, int type, void *cb, void *user,
                           uint64_t begin, uint64_t end, ...);
typedef int (*emu_stop_fn)(void *uc);
typedef int (*reg_read_fn)(void *uc, int regid, void *value);

enum { FAULT_NONE = 0, FAULT_READ = 1, FAULT_WRITE = 2, FAULT_BUDGET = 3, FAULT_PENDING = 4,
       FAULT_UNALIGNED = 5 };

typedef struct {
    /* set once by Python */
    emu_stop_fn emu_stop;
    reg_read_fn reg_read;
    int32_t reg_pc;
    uint32_t code_base, code_halfwords;
    const uint32_t *instr_prefix; /* code_halfwords + 1 entries */
    const uint32_t *cycle_prefix;
    const uint8_t *boundary;      /* 1 where an instruction starts (and at the end) */
    const uint8_t *strict;        /* 1 where an instruction needs aligned data (LDRD, LDM,
                                     VLDR, ...: a UsageFault on the Cortex-M4) */
    uint32_t branch_penalty;
    uint64_t budget_cycles;
    uint32_t rules_base[2], rules_bytes[2];
    const uint8_t *rules[2];      /* per byte of each window: 1 readable, 2 writable */
    uint32_t fsmc_lo, fsmc_hi, fsmc_extra_half, fsmc_extra_word;
    uint32_t *pending;            /* (address, size) pairs */
    uint32_t pending_cap;
    /* per step, cleared by Python */
    uint64_t instructions, cycles;
    uint32_t blocks, taken, fsmc_accesses, n_pending;
    uint32_t prev_end;
    uint32_t fault, fault_addr, fault_size, fault_pc;
} eha_prof;

static void stop(void *uc, eha_prof *p, uint32_t kind, uint32_t addr, uint32_t size)
{
    if (p->fault == FAULT_NONE) {
        uint32_t pc = 0;
        p->reg_read(uc, p->reg_pc, &pc);
        p->fault = kind;
        p->fault_addr = addr;
        p->fault_size = size;
        p->fault_pc = pc;
    }
    p->emu_stop(uc);
}

static void on_block(void *uc, uint64_t address, uint32_t size, void *user)
{
    eha_prof *p = user;
    uint32_t a = (uint32_t)address;
    p->blocks++;
    if (p->blocks > 1 && a != p->prev_end) {
        p->taken++;
        p->cycles += p->branch_penalty;
    }
    p->prev_end = a + size;
    uint32_t h0 = (a - p->code_base) >> 1, h1 = h0 + (size >> 1);
    if (a >= p->code_base && h1 <= p->code_halfwords && p->boundary[h0] && p->boundary[h1]) {
        p->instructions += p->instr_prefix[h1] - p->instr_prefix[h0];
        p->cycles += p->cycle_prefix[h1] - p->cycle_prefix[h0];
    } else if (p->n_pending < p->pending_cap) {
        p->pending[2 * p->n_pending] = a;
        p->pending[2 * p->n_pending + 1] = size;
        p->n_pending++;
        p->cycles += size >> 1; /* a floor until Python prices it */
    } else {
        stop(uc, p, FAULT_PENDING, a, size);
        return;
    }
    if (p->cycles > p->budget_cycles)
        stop(uc, p, FAULT_BUDGET, a, size);
}

static void on_access(void *uc, int type, uint64_t address, int size, int64_t value,
                      void *user)
{
    (void)value;
    eha_prof *p = user;
    uint32_t a = (uint32_t)address;
    int write = type == 17; /* UC_MEM_WRITE; UC_MEM_READ is 16 */
    if ((a & (uint32_t)(size - 1)) && size > 1) {
        uint32_t pc = 0;
        p->reg_read(uc, p->reg_pc, &pc);
        uint32_t h = (pc - p->code_base) >> 1;
        if (pc < p->code_base || h >= p->code_halfwords || p->strict[h]) {
            stop(uc, p, FAULT_UNALIGNED, a, (uint32_t)size);
            return;
        }
    }
    if (a < p->fsmc_lo || a > p->fsmc_hi)
        return;
    p->fsmc_accesses++;
    p->cycles += size > 2 ? p->fsmc_extra_word : p->fsmc_extra_half;
    uint8_t need = write ? 2 : 1;
    for (int w = 0; w < 2; w++) {
        if (a < p->rules_base[w] || a - p->rules_base[w] + (uint32_t)size > p->rules_bytes[w])
            continue; /* Unicorn's page permissions decide outside the windows */
        const uint8_t *r = p->rules[w] + (a - p->rules_base[w]);
        for (int k = 0; k < size; k++)
            if (!(r[k] & need)) {
                stop(uc, p, write ? FAULT_WRITE : FAULT_READ, a, (uint32_t)size);
                return;
            }
    }
}

/* Install both hooks on `uc`; 0 or Unicorn's error code. */
int eha_install(void *uc, hook_add_fn hook_add, eha_prof *p, int hook_block, int hook_read,
                int hook_write)
{
    size_t hh;
    int err = hook_add(uc, &hh, hook_block, (void *)on_block, p, (uint64_t)1, (uint64_t)0);
    if (err)
        return err;
    /* every access: the alignment check needs them all, the FSMC rules only theirs */
    return hook_add(uc, &hh, hook_read | hook_write, (void *)on_access, p, (uint64_t)1,
                    (uint64_t)0);
}

uint32_t eha_prof_size(void)
{
    return (uint32_t)sizeof(eha_prof);
}
