/* pong.c: the C pong of `nerve bench c` (row `c`), an event-driven nerve
 * agent written in C against libnerve: every sample arriving on `in` is
 * answered with one on `out`, as the Rust pong (`nerve-bench __agent-pong`)
 * does. The sample is read in place in shared memory (nerve_take) and only
 * its sequence number is written, in place, in a loaned slot that is not
 * zeroed (nerve_loan_uninit): the rest of the payload is never touched, so
 * the round trip is the same work at 8 B and at 1080p. Built with
 * -DPONG_LOAN_ZEROED it loans with nerve_loan instead, which zeroes the
 * whole slot first (the C API's only loan before nerve_loan_uninit).
 *
 * The bench compiles it at run time, with gcc -O2 against the release
 * libnerve, and starts it as any agent:
 *   cpong --robot R --name cpong-8 -- --size 8 */
#include "bench_payloads.h"
#include "nerve.h"

#include <stdio.h>
#include <string.h>

#ifdef PONG_LOAN_ZEROED
#define PONG_LOAN nerve_loan
#else
#define PONG_LOAN nerve_loan_uninit
#endif

typedef struct {
  nerve_port in;
  nerve_port out;
  const nerve_type *payload;
} pong;

static int fail(const char *what) {
  fprintf(stderr, "cpong: %s: %s\n", what, nerve_last_error());
  return 1;
}

static int pong_init(nerve_setup *setup, void *user) {
  pong *p = user;
  if (nerve_setup_input_type(setup, "in", p->payload, &p->in) != NERVE_OK) {
    return fail("input in");
  }
  if (nerve_setup_output_type(setup, "out", p->payload, &p->out) != NERVE_OK) {
    return fail("output out");
  }
  return 0;
}

static int pong_step(nerve_ctx *ctx, void *user) {
  pong *p = user;
  for (;;) {
    const void *data = NULL;
    size_t len = 0;
    nerve_status s = nerve_take(ctx, p->in, &data, &len);
    if (s == NERVE_NO_SAMPLE) {
      return 0;
    }
    if (s != NERVE_OK) {
      return fail("nerve_take");
    }
    if (len < sizeof(uint64_t)) {
      fprintf(stderr, "cpong: a sample of %zu bytes has no sequence number\n", len);
      return 1;
    }
    uint64_t seq = 0;
    memcpy(&seq, data, sizeof seq);
    void *slot = NULL;
    if (PONG_LOAN(ctx, p->out, &slot) != NERVE_OK) {
      return fail("loan");
    }
    memcpy(slot, &seq, sizeof seq);
    if (nerve_send(ctx, p->out) != NERVE_OK) {
      return fail("nerve_send");
    }
  }
}

static const nerve_agent_vtable pong_agent = {
    .kind = "bench-cpong",
    .period_ns = 0,
    .init = pong_init,
    .start = NULL,
    .step = pong_step,
    .stop = NULL,
};

int main(int argc, char **argv) {
  static pong p;
  size_t size = bench_size_arg(argc, argv);
  p.payload = bench_payload_of(size);
  if (p.payload == NULL) {
    fprintf(stderr, "cpong: no payload of %zu bytes; use --size 8, 4096, 230400 or 6220800\n", size);
    return 2;
  }
  return nerve_run(argc, argv, &pong_agent, &p);
}
