/* seq_call_test.c: the C sequence-and-call agent (seq_call.c) on nerve's C
 * test harness: sequences of any length queued on its input and read back
 * from its output, a loan past max_len refused, and every misuse of the
 * sequence and call functions (NULL, an unknown or wrong kind of port, a
 * length past the maximum, a context kept past its step) a status with a
 * message, never a crash. The test calls the agent's services
 * (nerve_harness_call, nerve_harness_call_take): a sequence answer written
 * in place by the agent, one past its max_len refused, a fixed answer;
 * tests/c_agent.rs checks its calls on a robot, against Rust agents.
 *
 * Run by agent-sdk-c/tests/c_harness.rs (plain and under ASan/UBSan).
 * Exits 0 when every check passed. */
#define NERVE_NO_MAIN
#include "seq_call.c"

#include <stdlib.h>
#include <string.h>
#include "harness_check.h"

/* A sequence sample as it lies in memory: the header, then the elements. */
typedef struct {
  detections_header h;
  detection d[401];
} dets_sample;

static size_t sample_len(size_t n) { return sizeof(detections_header) + n * sizeof(detection); }

/* Queues a sample of n detections (j at y = frame, id = j) on dets_in. */
static void queue_dets(nerve_harness *h, dets_sample *s, uint64_t frame, size_t n) {
  memset(s, 0, sizeof *s);
  s->h.frame = frame;
  s->h.count = (uint32_t)n;
  for (size_t j = 0; j < n; j++) {
    s->d[j].x = (float)j;
    s->d[j].y = (float)frame;
    s->d[j].id = (uint32_t)j;
  }
  expect("send a sequence", nerve_harness_send(h, "dets_in", s, sample_len(n)), NERVE_OK);
}

/* What the misuse step saw (each status and its message), checked after it. */
static nerve_ctx *kept = NULL;
static nerve_status seen[10];
static char said[10][512];

/* Keeps call i's status and message. */
static void see(int i, nerve_status st) {
  seen[i] = st;
  snprintf(said[i], sizeof said[i], "%s", nerve_last_error());
}

/* Checks a kept status: `want`, and a message with any failure. */
static void expect_seen(int i, const char *what, nerve_status want) {
  if (seen[i] != want) {
    printf("FAIL %s: status %d, not %d (%s)\n", what, (int)seen[i], (int)want, said[i]);
    failures++;
  } else if (want != NERVE_OK && strlen(said[i]) == 0) {
    printf("FAIL %s: status %d without a message\n", what, (int)seen[i]);
    failures++;
  } else {
    printf("ok %s%s%s\n", what, want == NERVE_OK ? "" : ": ", said[i]);
  }
}

static int misuse_step(nerve_ctx *ctx, void *user) {
  agent *a = user;
  kept = ctx;
  nerve_seq s;
  nerve_seq_loan l;
  see(0, nerve_take_seq(ctx, a->dets_in, NULL));
  see(1, nerve_take_seq(ctx, a->dets, &s));      /* an output's handle */
  see(2, nerve_loan_seq(ctx, a->rep, 1, &l));    /* not a sequence */
  see(3, nerve_loan_seq(ctx, a->dets, 1001, &l)); /* past max_len */
  see(4, nerve_loan_seq(ctx, a->dets, 2, &l));
  see(5, nerve_loan_seq(ctx, a->dets, 2, &l)); /* one loan per output at a time */
  see(6, nerve_serve(ctx, a->planner, answer_plan, a, NULL)); /* a client's handle */
  see(7, nerve_serve(ctx, a->plan_seq, answer_plan, a, NULL)); /* a sequence service */
  see(8, nerve_serve_seq(ctx, a->plan, answer_path, a, NULL)); /* a fixed service */
  see(9, nerve_call_take_seq(ctx, a->planner_seq, NULL, NULL));
  return 0;
}

static void runs_in_the_harness(void) {
  static agent a;
  static dets_sample in, out;
  memset(&a, 0, sizeof a);
  nerve_harness *h = NULL;
  expect("start the agent (its calls kept, not carried)", nerve_harness_new(&cseq_agent, &a, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  queue_dets(h, &in, 7, 0);
  queue_dets(h, &in, 7, 1);
  queue_dets(h, &in, 7, 401);
  uint64_t steps = 0;
  expect("advance 60 ms", nerve_harness_advance(h, 60000000u, &steps), NERVE_OK);
  expect_true("3 steps of 20 ms", steps == 3);
  /* the three samples it sent: 0, 1 and 400 detections, written in place */
  const size_t want[3] = {0, 1, 400};
  for (int k = 0; k < 3; k++) {
    size_t len = 0;
    expect("read a sequence", nerve_harness_output(h, "dets", &out, sizeof out, &len), NERVE_OK);
    int right = len == sample_len(want[k]) && out.h.frame == (uint64_t)k + 1 && out.h.count == want[k];
    for (size_t j = 0; right && j < want[k]; j++) {
      right = out.d[j].id == j && out.d[j].y == (float)(k + 1);
    }
    expect_true("a sequence at its own length, every element as written", right);
  }
  report r;
  size_t len = 0;
  for (int k = 0; k < 3; k++) {
    expect("read a report", nerve_harness_output(h, "report", &r, sizeof r, &len), NERVE_OK);
  }
  expect_true("it read the 3 sequences in place, the largest of 401, none bad",
              r.received == 3 && r.largest == 401 && r.bad == 0);
  expect_true("a loan past max_len refused every step", r.refused == 3);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

/* An answer of plan_seq as it lies in memory: the request's tick, then the scalars. */
typedef struct {
  nerve_Tick h;
  nerve_Scalar s[8];
} path_sample;

/* The test calls the agent's services: a sequence answer written in place
 * by the agent, one past its max_len refused, a fixed answer. */
static void calls_in_the_harness(void) {
  static agent a;
  memset(&a, 0, sizeof a);
  nerve_harness *h = NULL;
  expect("start the agent", nerve_harness_new(&cseq_agent, &a, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  nerve_Tick ask = {3, 77}, past = {501, 78}, fixed = {21, 79};
  uint64_t asked = 0, refused = 0, plain = 0, id = 7;
  expect("call plan_seq (3 elements)", nerve_harness_call(h, "plan_seq", &ask, sizeof ask, &asked), NERVE_OK);
  expect("call plan_seq (501, past max_len)", nerve_harness_call(h, "plan_seq", &past, sizeof past, &refused), NERVE_OK);
  expect("call plan", nerve_harness_call(h, "plan", &fixed, sizeof fixed, &plain), NERVE_OK);
  expect("call with a request of another size", nerve_harness_call(h, "plan_seq", &ask, 4, &id), NERVE_LAYOUT_MISMATCH);
  expect("call an unknown service", nerve_harness_call(h, "nope", &ask, sizeof ask, &id), NERVE_UNKNOWN_PORT);
  expect_true("a refused call has no id", id == 0);
  path_sample p;
  size_t len = 9;
  expect("no answer before the step", nerve_harness_call_take(h, "plan_seq", &id, &p, sizeof p, &len),
         NERVE_NO_SAMPLE);
  expect("step", nerve_harness_step(h), NERVE_OK);
  memset(&p, 0xff, sizeof p);
  expect("take plan_seq's answer", nerve_harness_call_take(h, "plan_seq", &id, &p, sizeof p, &len), NERVE_OK);
  int right = id == asked && len == sizeof(nerve_Tick) + 3 * sizeof(nerve_Scalar) && p.h.seq == 3 && p.h.stamp_ns == 77;
  for (size_t i = 0; right && i < 3; i++) {
    right = p.s[i].value == (double)i && p.s[i].stamp_ns == 77;
  }
  expect_true("a sequence answer of 3 elements, written in place by the agent", right);
  nerve_status st = nerve_harness_call_take(h, "plan_seq", &id, &p, sizeof p, &len);
  int says = strstr(nerve_last_error(), "refused") != NULL;
  expect("the answer past max_len: refused", st, NERVE_CALL_FAILED);
  expect_true("the refused call named, no bytes, the message says refused", id == refused && len == 0 && says);
  expect("nothing more", nerve_harness_call_take(h, "plan_seq", &id, &p, sizeof p, &len), NERVE_NO_SAMPLE);
  nerve_Scalar s;
  expect("take plan's answer", nerve_harness_call_take(h, "plan", &id, &s, sizeof s, &len), NERVE_OK);
  expect_true("a fixed answer: twice the seq", id == plain && len == sizeof s && s.value == 42.0);
  report r;
  expect("read a report", nerve_harness_output(h, "report", &r, sizeof r, &len), NERVE_OK);
  expect_true("the agent answered one sequence, refused one, and one fixed",
              r.seq_answered == 1 && r.seq_refused == 1 && r.answered == 1);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

static void misuse(void) {
  static agent a;
  memset(&a, 0, sizeof a);
  nerve_agent_vtable m = cseq_agent;
  m.step = misuse_step;
  nerve_harness *h = NULL;
  expect("start", nerve_harness_new(&m, &a, NULL, 0, &h), NERVE_OK);
  if (h == NULL) {
    failures++;
    return;
  }
  expect("step", nerve_harness_step(h), NERVE_OK);
  expect_seen(0, "take_seq(NULL seq)", NERVE_NULL_POINTER);
  expect_seen(1, "take_seq(an output)", NERVE_UNKNOWN_PORT);
  expect_seen(2, "loan_seq(not a sequence)", NERVE_INVALID_ARGUMENT);
  expect_seen(3, "loan_seq(past max_len)", NERVE_TOO_LONG);
  expect_seen(4, "loan_seq(2)", NERVE_OK);
  expect_seen(5, "loan_seq(a loan pending)", NERVE_LOAN_PENDING);
  expect_seen(6, "serve(a client's handle)", NERVE_UNKNOWN_PORT);
  expect_seen(7, "serve(a sequence service)", NERVE_UNKNOWN_PORT);
  expect_seen(8, "serve_seq(a fixed service)", NERVE_UNKNOWN_PORT);
  expect_seen(9, "call_take_seq(NULL answer)", NERVE_NULL_POINTER);
  nerve_seq_loan none;
  expect("answer_loan(NULL answer)", nerve_answer_loan(NULL, 1, &none), NERVE_NULL_POINTER);
  size_t len = 0;
  dets_sample out;
  expect("a loan not sent was not sent", nerve_harness_output(h, "dets", &out, sizeof out, &len), NERVE_NO_SAMPLE);
  /* the step's context, kept past it */
  nerve_seq s = {&s, &s, 7};
  nerve_seq_loan l = {&l, &l, 7};
  expect("take_seq(a context kept past its step)", nerve_take_seq(kept, a.dets_in, &s), NERVE_STALE);
  expect("latest_seq(a context kept past its step)", nerve_latest_seq(kept, a.dets_in, &s), NERVE_STALE);
  expect("loan_seq(a context kept past its step)", nerve_loan_seq(kept, a.dets, 1, &l), NERVE_STALE);
  expect("serve(a context kept past its step)", nerve_serve(kept, a.plan, answer_plan, &a, NULL), NERVE_STALE);
  expect("serve_seq(a context kept past its step)", nerve_serve_seq(kept, a.plan_seq, answer_path, &a, NULL),
         NERVE_STALE);
  expect_true("a refused call hands out no pointer",
              s.header == NULL && s.items == NULL && s.len == 0 && l.header == NULL && l.items == NULL);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

/* Declarations refused in init, each with its status. */
static int bad_init(nerve_setup *setup, void *user) {
  (void)user;
  nerve_port p = 0;
  static const nerve_type nope = {"acme::Nope", 4, 4, NULL, 0};
  static const nerve_type small_tick = {"nerve::Tick", 8, 8, NULL, 0};
  static const nerve_type u8 = NERVE_BUILTIN_PRIMITIVE(uint8_t, "u8");
  see(0, nerve_setup_output_seq(setup, "a", NULL, NULL, 10, &p));
  see(1, nerve_setup_output_seq(setup, "b", &nope, NULL, 10, &p));
  see(2, nerve_setup_output_seq(setup, "c", &small_tick, NULL, 10, &p));
  see(3, nerve_setup_output_seq(setup, "d", &u8, NULL, (size_t)1 << 40, &p));
  see(4, nerve_setup_output_seq(setup, "text", &u8, NULL, 256, &p)); /* a Seq<u8>: fine */
  return 0;
}

static void refused_declarations(void) {
  nerve_agent_vtable v = cseq_agent;
  v.init = bad_init;
  nerve_harness *h = NULL;
  expect("start", nerve_harness_new(&v, NULL, NULL, 0, &h), NERVE_OK);
  expect_seen(0, "output_seq(NULL element)", NERVE_NULL_POINTER);
  expect_seen(1, "output_seq(no such type)", NERVE_UNKNOWN_TYPE);
  expect_seen(2, "output_seq(a built-in of another size)", NERVE_LAYOUT_MISMATCH);
  expect_seen(3, "output_seq(max_len past 64 MiB)", NERVE_INVALID_ARGUMENT);
  expect_seen(4, "output_seq(a sequence of u8)", NERVE_OK);
  expect("free", nerve_harness_free(h), NERVE_OK);
}

int main(void) {
  runs_in_the_harness();
  calls_in_the_harness();
  misuse();
  refused_declarations();
  printf("%s: %d failure(s)\n", failures ? "FAILED" : "PASSED", failures);
  return failures ? 1 : 0;
}
