// The current loop's Verilated model behind a C ABI (hil/sim/verilator.py builds it
// with the generated port code below; firmware_model/fpga/rtl_abi.py calls it per tick).
//
// Timing: clk is the control tick. Per 50 us tick the inputs are applied with clk low, the
// combinational datapath settles (eval), every output port is read, then one rising edge
// stores the integrators. The buffer ``io`` holds the words (layout: rtl_abi.IO_*).
#include <cstdint>

#include "verilated.h"
#include "Vcurrent_loop.h"

namespace {

struct Loop {
    VerilatedContext context;
    Vcurrent_loop* top;
    int64_t* io;
};

inline int64_t sign_extend(uint64_t v, int width) {
    return static_cast<int64_t>(v << (64 - width)) >> (64 - width);
}

// Generated from the port tables: apply_inputs(top, in), read_outputs(top, out).
@PORT_CODE@

inline void settle(Loop* m, const int64_t* in, int64_t* out) {
    Vcurrent_loop* t = m->top;
    t->clk = 0;
    apply_inputs(t, in);
    t->eval();
    read_outputs(t, out);
}

inline void rising_edge(Loop* m) {
    m->top->clk = 1;
    m->top->eval();
}

}  // namespace

extern "C" {

int64_t eha_rtl_abi(void) { return @ABI@; }

void* eha_rtl_new(int64_t* io) {
    Loop* m = new Loop;
    m->io = io;
    m->top = new Vcurrent_loop(&m->context, "current_loop");
    // Synchronous reset: one edge with rst high.
    m->top->rst = 1;
    m->top->clk = 0;
    m->top->eval();
    rising_edge(m);
    m->top->rst = 0;
    m->top->clk = 0;
    m->top->eval();
    return m;
}

void eha_rtl_free(void* handle) {
    Loop* m = static_cast<Loop*>(handle);
    m->top->final();
    delete m->top;
    delete m;
}

// One control tick on the buffer: inputs at io[IN], outputs to io[OUT], edge if io[EDGE].
void eha_rtl_tick(void* handle) {
    Loop* m = static_cast<Loop*>(handle);
    settle(m, m->io + @IO_IN@, m->io + @IO_OUT@);
    if (m->io[@IO_EDGE@]) rising_edge(m);
}

// n ticks of vectors (each a rising edge): in n x @N_IN@ words, out n x @N_OUT@ words.
void eha_rtl_run(void* handle, const int64_t* in, int64_t* out, int64_t n) {
    Loop* m = static_cast<Loop*>(handle);
    for (int64_t k = 0; k < n; ++k) {
        settle(m, in + k * @N_IN@, out + k * @N_OUT@);
        rising_edge(m);
    }
}

}  // extern "C"
