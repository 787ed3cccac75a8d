/* Unicorn callbacks for a firmware image in the loop, in C because they run on every
 * instruction and every external-bus access (a Python callback costs ~2 us, which would
 * take the image below real time). Unicorn's functions come in as pointers from the
 * Python binding's library, so this file needs no Unicorn headers.
 *
 * No UC_HOOK_MEM_* hooks: with them, Unicorn 2.1 leaves a Thumb IT block's condition
 * state set after the block (an instruction after it is skipped; unicorn-engine/unicorn
 * issue 2309). The external bus is MMIO instead, and alignment is checked per instruction.
 *
 * Per instruction (a code hook over all memory): the instruction and its estimated cycles
 * from a per-halfword table of flash (hil/sim/image/cost.py); a taken-branch penalty when it
 * does not follow the previous one. Unicorn calls the code hook for some instructions inside
 * a Thumb IT block and not for others (not for the last), so the table charges an IT
 * instruction with its whole block (each instruction at its full cost, whether its
 * condition passes or not: an upper bound), the next expected address is the block's end,
 * and a hook call inside a block counts nothing; the address of the last instruction, for fault
 * reports; the Cortex-M4's UNALIGNED UsageFault for LDRD/STRD/LDM/STM/VLDR/VSTR, whose
 * effective address is its base register plus an offset taken from the disassembly; a
 * stop when the step exceeds its cycle budget. Code outside flash goes to a pending list
 * that Python prices after the step.
 * Per external-bus (FSMC) access: MMIO reads and writes of the DPRAM and process-data
 * pages (numpy memory), checked against per-byte rules (read, write), plus the wait states
 * of the transfer; a violation stops the run with address, size and instruction. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

typedef int (*hook_add_fn)(void *uc, size_t *hh, int type, void *cb, void *user,
                           uint64_t begin, uint64_t end, ...);
typedef int (*mmio_map_fn)(void *uc, uint64_t address, size_t size, void *read_cb,
                           void *user_read, void *write_cb, void *user_write);
typedef int (*emu_stop_fn)(void *uc);
typedef int (*reg_read_fn)(void *uc, int regid, void *value);

enum { FAULT_NONE = 0, FAULT_READ = 1, FAULT_WRITE = 2, FAULT_BUDGET = 3, FAULT_PENDING = 4,
       FAULT_UNALIGNED = 5 };

typedef struct {
    uint8_t *memory;     /* the page's bytes */
    const uint8_t *rules; /* per byte: 1 readable, 2 writable */
    uint32_t base, bytes;
    void *prof;
} eha_window;

typedef struct {
    /* set once by Python */
    emu_stop_fn emu_stop;
    reg_read_fn reg_read;
    uint32_t code_base, code_halfwords;
    const uint16_t *cost;         /* per halfword of flash: cycles of the instruction there */
    const uint8_t *count;         /* instructions it stands for (an IT: itself and its block;
                                     an instruction inside a block: 0) */
    const uint8_t *span;          /* bytes it stands for (an IT: up to the block's end);
                                     0: no instruction starts here */
    const int16_t *strict_reg;    /* Unicorn register id of the base, 0: no alignment rule */
    const int16_t *strict_off;    /* offset added to it */
    uint32_t branch_penalty;
    uint64_t budget_cycles;
    uint32_t fsmc_extra_half, fsmc_extra_word;
    uint32_t *pending;            /* (address, size) pairs */
    uint32_t pending_cap;
    /* per step, cleared by Python */
    uint64_t instructions, cycles;
    uint32_t taken, fsmc_accesses, n_pending;
    uint32_t next_pc, last_pc;
    uint32_t fault, fault_addr, fault_size, fault_pc;
} eha_prof;

static void stop(void *uc, eha_prof *p, uint32_t kind, uint32_t addr, uint32_t size)
{
    if (p->fault == FAULT_NONE) {
        p->fault = kind;
        p->fault_addr = addr;
        p->fault_size = size;
        p->fault_pc = p->last_pc;
    }
    p->emu_stop(uc);
}

static void on_code(void *uc, uint64_t address, uint32_t size, void *user)
{
    eha_prof *p = user;
    uint32_t a = (uint32_t)address;
    uint32_t h = (a - p->code_base) >> 1;
    int known = a >= p->code_base && h < p->code_halfwords && p->span[h];
    p->last_pc = a;
    if (known && !p->count[h])
        return; /* inside an IT block: charged with its IT instruction */
    if (p->instructions && a != p->next_pc) {
        p->taken++;
        p->cycles += p->branch_penalty;
    }
    if (known) {
        p->instructions += p->count[h];
        p->next_pc = a + p->span[h];
        p->cycles += p->cost[h];
        int reg = p->strict_reg[h];
        if (reg) {
            uint32_t base = 0;
            p->reg_read(uc, reg, &base);
            uint32_t ea = base + (uint32_t)(int32_t)p->strict_off[h];
            if (ea & 3u)
                stop(uc, p, FAULT_UNALIGNED, ea, 4);
        }
    } else if (p->n_pending < p->pending_cap) {
        p->instructions++;
        p->next_pc = a + size;
        p->pending[2 * p->n_pending] = a;
        p->pending[2 * p->n_pending + 1] = size;
        p->n_pending++;
        p->cycles += 1; /* a floor until Python prices it */
    } else {
        p->instructions++;
        stop(uc, p, FAULT_PENDING, a, size);
    }
    if (p->cycles > p->budget_cycles)
        stop(uc, p, FAULT_BUDGET, a, size);
}

static int allowed(void *uc, eha_window *w, uint64_t offset, unsigned size, uint8_t need)
{
    eha_prof *p = w->prof;
    p->fsmc_accesses++;
    p->cycles += size > 2 ? p->fsmc_extra_word : p->fsmc_extra_half;
    if (offset + size > w->bytes)
        goto bad;
    for (unsigned k = 0; k < size; k++)
        if (!(w->rules[offset + k] & need))
            goto bad;
    return 1;
bad:
    stop(uc, p, need == 2 ? FAULT_WRITE : FAULT_READ, w->base + (uint32_t)offset, size);
    return 0;
}

static uint64_t on_read(void *uc, uint64_t offset, unsigned size, void *user)
{
    eha_window *w = user;
    uint64_t v = 0;
    if (allowed(uc, w, offset, size, 1))
        memcpy(&v, w->memory + offset, size); /* little-endian host and target */
    return v;
}

static void on_write(void *uc, uint64_t offset, unsigned size, uint64_t value, void *user)
{
    eha_window *w = user;
    if (allowed(uc, w, offset, size, 2))
        memcpy(w->memory + offset, &value, size);
}

/* Install the code hook and map the two FSMC windows; 0 or Unicorn's error code. */
int eha_install(void *uc, hook_add_fn hook_add, mmio_map_fn mmio_map, eha_prof *p,
                int hook_code, eha_window *windows, int n_windows)
{
    size_t hh;
    int err = hook_add(uc, &hh, hook_code, (void *)on_code, p, (uint64_t)1, (uint64_t)0);
    for (int k = 0; !err && k < n_windows; k++) {
        windows[k].prof = p;
        err = mmio_map(uc, windows[k].base, windows[k].bytes, (void *)on_read, &windows[k],
                       (void *)on_write, &windows[k]);
    }
    return err;
}
