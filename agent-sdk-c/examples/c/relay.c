/* relay.c: a nerve agent written in C. It republishes every nerve::Tick
 * that arrives on its input `in` on its output `out`, read and written in
 * place in shared memory (no copy through nerve, one struct copy here).
 *
 * Build (from the nerve tree, after `cargo build -p nerve-agent-c`):
 *   gcc -std=c11 -Wall -Wextra -I agent-sdk-c/include agent-sdk-c/examples/c/relay.c \
 *       -L target/debug -lnerve -Wl,-rpath,$PWD/target/debug -o crelay
 * and run it as any agent: from a launch file (`exe = "/path/to/crelay"`),
 * or `./crelay --describe`. */
#include "nerve.h"
#include "nerve_types.h" /* nerve_Tick: seq, stamp_ns, as shm-schemas lays it out */

#include <stdint.h>
#include <stdio.h>

/* 0: step when a tick arrives. Build with -DRELAY_PERIOD_NS=20000000 for a
 * relay that steps every 20 ms instead, taking all that waits (then
 * `nerve rate` changes its period, as for any periodic agent). */
#ifndef RELAY_PERIOD_NS
#define RELAY_PERIOD_NS 0
#endif

/* The agent's state: nerve hands this pointer to every callback. */
typedef struct {
  nerve_port in;
  nerve_port out;
  uint64_t relayed;
} relay;

static int fail(const char *what) {
  fprintf(stderr, "crelay: %s: %s\n", what, nerve_last_error());
  return 1;
}

static int relay_init(nerve_setup *setup, void *user) {
  relay *r = user;
  /* the type's name, size, alignment and layout fingerprint, checked by nerve */
  if (NERVE_SETUP_INPUT(setup, "in", nerve_Tick, &r->in) != NERVE_OK) {
    return fail("input in");
  }
  if (NERVE_SETUP_OUTPUT(setup, "out", nerve_Tick, &r->out) != NERVE_OK) {
    return fail("output out");
  }
  return 0;
}

static int relay_step(nerve_ctx *ctx, void *user) {
  relay *r = user;
  for (;;) {
    const void *data = NULL;
    size_t len = 0;
    nerve_status s = nerve_take(ctx, r->in, &data, &len);
    if (s == NERVE_NO_SAMPLE) {
      return 0;
    }
    if (s != NERVE_OK) {
      return fail("take");
    }
    if (len != sizeof(nerve_Tick)) {
      fprintf(stderr, "crelay: a sample of %zu bytes, not a nerve_Tick\n", len);
      return 1;
    }
    const nerve_Tick *in = data;
    void *slot = NULL;
    if (nerve_loan(ctx, r->out, &slot) != NERVE_OK) {
      return fail("loan");
    }
    nerve_Tick *out = slot;
    out->seq = in->seq;
    out->stamp_ns = in->stamp_ns;
    if (nerve_send(ctx, r->out) != NERVE_OK) {
      return fail("send");
    }
    r->relayed++;
  }
}

static void relay_stop(nerve_ctx *ctx, void *user) {
  (void)ctx;
  relay *r = user;
  fprintf(stderr, "crelay: stopping after %llu ticks\n", (unsigned long long)r->relayed);
}

/* The agent as nerve runs it; relay_test.c runs the same callbacks in a
 * test harness. */
static const nerve_agent_vtable relay_agent = {
    .kind = "crelay",
    .period_ns = RELAY_PERIOD_NS,
    .init = relay_init,
    .start = NULL,
    .step = relay_step,
    .stop = relay_stop,
};

/* relay_test.c includes this file with NERVE_NO_MAIN defined, to run the
 * agent's callbacks in its own main. */
#ifndef NERVE_NO_MAIN
int main(int argc, char **argv) {
  static relay r;
  return nerve_run(argc, argv, &relay_agent, &r);
}
#endif
