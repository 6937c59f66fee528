/* relay_test.c: the C relay (relay.c) tested with nerve's C test harness:
 * its own init and step run in this process, with no router and no shared
 * memory, on a clock the test moves. Ticks are queued on `in`, the steps
 * run, what `out` sent is read back; then every misuse of the harness (a
 * NULL pointer, an unknown port, a wrong size, a context kept past its
 * step) must be a status with a message, never a crash.
 *
 * Build and run (from the nerve tree, after `cargo build -p nerve-agent-c`):
 *   gcc -std=c11 -Wall -Wextra -I agent-sdk-c/include agent-sdk-c/examples/c/relay_test.c \
 *       -L target/debug -lnerve -Wl,-rpath,$PWD/target/debug -o relay_test && ./relay_test
 * agent-sdk-c/tests/c_harness.rs runs it, also built with
 * -fsanitize=address,undefined. Exits 0 when every check passed. */
#define NERVE_NO_MAIN
#include "relay.c"

#include <string.h>
#include "harness_check.h"

/* Queues ticks 1..n on the relay's input. */
static void send_ticks(nerve_harness *h, uint64_t n) {
  for (uint64_t i = 1; i <= n; i++) {
    nerve_Tick t = {.seq = i, .stamp_ns = 1000 * i};
    expect("send a tick", nerve_harness_send(h, "in", &t, sizeof t), NERVE_OK);
  }
}

/* Reads what `out` sent; checks they are ticks first..first+n-1 in order. */
static void expect_relayed(nerve_harness *h, uint64_t first, uint64_t n) {
  for (uint64_t i = 0; i < n; i++) {
    nerve_Tick t;
    size_t len = 0;
    expect("read a tick", nerve_harness_output(h, "out", &t, sizeof t, &len), NERVE_OK);
    expect_true("the tick is relayed whole and in order",
                len == sizeof t && t.seq == first + i && t.stamp_ns == 1000 * (first + i));
  }
  nerve_Tick t;
  size_t len = 1;
  expect("nothing more was sent", nerve_harness_output(h, "out", &t, sizeof t, &len), NERVE_NO_SAMPLE);
  expect_true("no sample, no length", len == 0);
}

/* The event-driven relay: what arrives is sent on, the step and clock are the test's. */
static void event_driven(void) {
  relay r = {0};
  nerve_harness *h = NULL;
  expect("start the relay", nerve_harness_new(&relay_agent, &r, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  send_ticks(h, 3);
  expect("step", nerve_harness_step(h), NERVE_OK);
  expect_relayed(h, 1, 3);
  expect_true("the relay counted 3", r.relayed == 3);
  uint64_t now = 0, cycles = 0;
  expect("clock", nerve_harness_clock(h, &now, &cycles), NERVE_OK);
  expect_true("one step, clock at its start (1 s)", cycles == 1 && now == 1000000000u);
  expect("advance the clock", nerve_harness_advance(h, 500000000u, NULL), NERVE_OK);
  expect("clock", nerve_harness_clock(h, &now, NULL), NERVE_OK);
  expect_true("the clock moved 0.5 s, and only when told", now == 1500000000u);
  expect("free runs the relay's stop", nerve_harness_free(h), NERVE_OK);
}

/* The same callbacks as a periodic agent: the clock drives the steps. */
static void periodic(void) {
  relay r = {0};
  nerve_agent_vtable every_20ms = relay_agent;
  every_20ms.period_ns = 20000000u;
  nerve_harness *h = NULL;
  expect("start a periodic relay", nerve_harness_new(&every_20ms, &r, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  send_ticks(h, 2);
  uint64_t steps = 0;
  expect("advance 100 ms", nerve_harness_advance(h, 100000000u, &steps), NERVE_OK);
  expect_true("5 steps of 20 ms in 100 ms", steps == 5);
  expect_relayed(h, 1, 2);
  expect("rate 50 ms", nerve_harness_set_period(h, 50000000u), NERVE_OK);
  expect("advance 100 ms", nerve_harness_advance(h, 100000000u, &steps), NERVE_OK);
  expect_true("2 steps of 50 ms in 100 ms", steps == 2);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

/* An agent that keeps its step's context past the step, on purpose. */
static nerve_ctx *kept = NULL;
static int keep_step(nerve_ctx *ctx, void *user) {
  kept = ctx;
  return relay_step(ctx, user);
}
/* An agent whose step fails, with a message. */
static int failing_step(nerve_ctx *ctx, void *user) {
  (void)user;
  const void *data = NULL;
  size_t len = 0;
  return nerve_take(ctx, 99, &data, &len) == NERVE_OK ? 0 : 1;
}

static void misuse(void) {
  relay r = {0};
  nerve_harness *h = NULL;
  nerve_Tick t = {0};
  size_t len = 0;
  expect("new(NULL agent)", nerve_harness_new(NULL, &r, NULL, 0, &h), NERVE_NULL_POINTER);
  expect("new(NULL out)", nerve_harness_new(&relay_agent, &r, NULL, 0, NULL), NERVE_NULL_POINTER);
  const char *bad_setting[] = {"gain"};
  expect("new(a setting without =)", nerve_harness_new(&relay_agent, &r, bad_setting, 1, &h), NERVE_INVALID_ARGUMENT);
  const char *unknown[] = {"gain=2"};
  expect("new(a parameter it does not have)", nerve_harness_new(&relay_agent, &r, unknown, 1, &h),
         NERVE_INVALID_ARGUMENT);
  expect_true("a failed new leaves no harness", h == NULL);
  expect("step(NULL)", nerve_harness_step(NULL), NERVE_NULL_POINTER);
  expect("send(NULL)", nerve_harness_send(NULL, "in", &t, sizeof t), NERVE_NULL_POINTER);
  expect("output(NULL)", nerve_harness_output(NULL, "out", &t, sizeof t, &len), NERVE_NULL_POINTER);
  expect("free(NULL) does nothing", nerve_harness_free(NULL), NERVE_OK);

  nerve_agent_vtable keeper = relay_agent;
  keeper.step = keep_step;
  expect("start", nerve_harness_new(&keeper, &r, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  expect("send(NULL data)", nerve_harness_send(h, "in", NULL, sizeof t), NERVE_NULL_POINTER);
  expect("send(NULL port name)", nerve_harness_send(h, NULL, &t, sizeof t), NERVE_NULL_POINTER);
  expect("send(unknown input)", nerve_harness_send(h, "inn", &t, sizeof t), NERVE_UNKNOWN_PORT);
  expect("send(an output's name)", nerve_harness_send(h, "out", &t, sizeof t), NERVE_UNKNOWN_PORT);
  expect("send(wrong size)", nerve_harness_send(h, "in", &t, sizeof t - 1), NERVE_LAYOUT_MISMATCH);
  expect("output(unknown output)", nerve_harness_output(h, "outt", &t, sizeof t, &len), NERVE_UNKNOWN_PORT);
  expect("output(wrong size)", nerve_harness_output(h, "out", &t, sizeof t + 8, &len), NERVE_LAYOUT_MISMATCH);
  expect("output(NULL dst)", nerve_harness_output(h, "out", NULL, sizeof t, &len), NERVE_NULL_POINTER);
  expect("output(NULL len)", nerve_harness_output(h, "out", &t, sizeof t, NULL), NERVE_NULL_POINTER);
  expect("set_param(unknown key)", nerve_harness_set_param(h, "gain", "2"), NERVE_INVALID_ARGUMENT);
  expect("set_period(0)", nerve_harness_set_period(h, 0), NERVE_INVALID_ARGUMENT);
  send_ticks(h, 1);
  expect("step", nerve_harness_step(h), NERVE_OK);
  expect_relayed(h, 1, 1);
  /* the context given to the step, used after it returned */
  const void *data = NULL;
  void *slot = NULL;
  expect("take(a context kept past its step)", nerve_take(kept, r.in, &data, &len), NERVE_STALE);
  expect("loan(a context kept past its step)", nerve_loan(kept, r.out, &slot), NERVE_STALE);
  expect_true("a refused call hands out no pointer", data == NULL && slot == NULL);
  expect("free", nerve_harness_free(h), NERVE_OK);

  nerve_agent_vtable failing = relay_agent;
  failing.step = failing_step;
  expect("start", nerve_harness_new(&failing, &r, NULL, 0, &h), NERVE_OK);
  expect("a failed step is the agent's failure", nerve_harness_step(h), NERVE_AGENT_FAILED);
  expect_true("its message says what the step did wrong", strstr(nerve_last_error(), "handle 99") != NULL);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

int main(void) {
  event_driven();
  periodic();
  misuse();
  printf("%s: %d failure(s)\n", failures ? "FAILED" : "PASSED", failures);
  return failures ? 1 : 0;
}
