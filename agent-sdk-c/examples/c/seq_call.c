/* seq_call.c: a C agent with sequences and calls (issue 43). It is the C
 * twin of the Rust test agent `detector` (tests/src/bin/detector.rs) and
 * of both sides of `nerve-caller` (tests/src/bin/caller.rs), so a test
 * wires it to them both ways:
 *
 * - output `dets`: sequences of acme::Detection after an
 *   acme::DetectionsHeader, at most 1,000 a sample. Step n sends
 *   LENGTHS[(n - 1) % 4] detections (0, 1, 400, 401), detection j at
 *   x = j, y = n, id = j, written in place in shared memory; and tries
 *   1,001, which nerve refuses (NERVE_TOO_LONG, nothing loaned);
 * - input `dets_in` of the same type, read in place and checked
 *   element by element;
 * - service `plan`: a nerve::Tick answered with a nerve::Scalar of value
 *   2 * seq (as nerve-caller --serve answers);
 * - client `planner` of such a service (300 ms timeout): one call in
 *   flight (nerve_call, then nerve_call_take in a later step), and every
 *   tenth step one call that waits in the step (nerve_call_wait);
 * - service `plan_seq`: a nerve::Tick answered with a sequence of
 *   nerve::Scalar after a nerve::Tick (`Seq<Scalar, Tick>`, as
 *   nerve-caller --serve --seq answers): the request as header, then seq
 *   scalars 0, 1, ... written in place, at most 500 (past them the loan is
 *   refused, NERVE_TOO_LONG, and the caller told so);
 * - client `planner_seq` of such a service: one call in flight of a
 *   length (37 n) % 400, its answer read in place (nerve_call_take_seq)
 *   and checked element by element;
 * - output `report` (ctest::Report, a struct of its own): what it read,
 *   refused and was answered, since a C agent has no figures.
 *
 * Build: gcc -std=c11 -I agent-sdk-c/include seq_call.c -L target/debug -lnerve ...
 * (see relay.c); run from a launch file (`exe = "/path/to/cseq"`). */
#include "nerve.h"
#include "nerve_types.h"

#include <stdint.h>
#include <stdio.h>

/* The Rust detector's element and header, laid out as Rust lays them out. */
typedef struct {
  float x;
  float y;
  uint32_t id;
} detection;
static const nerve_field detection_fields[] = {
    NERVE_FIELD(detection, x, NERVE_F32), NERVE_FIELD(detection, y, NERVE_F32), NERVE_FIELD(detection, id, NERVE_U32)};
static const nerve_type detection_type = NERVE_TYPE(detection, "acme::Detection", detection_fields);

typedef struct {
  uint64_t frame;
  uint32_t count;
  uint8_t pad[4]; /* padding: not a field of the layout (the Rust struct skips it too) */
} detections_header;
static const nerve_field header_fields[] = {NERVE_FIELD(detections_header, frame, NERVE_U64),
                                            NERVE_FIELD(detections_header, count, NERVE_U32)};
static const nerve_type header_type = NERVE_TYPE(detections_header, "acme::DetectionsHeader", header_fields);

/* What it reports, every step. */
typedef struct {
  uint64_t received; /* sequence samples read on dets_in */
  uint64_t largest;  /* the most elements one held */
  uint64_t bad;      /* samples whose elements were not the ones sent */
  uint64_t refused;  /* loans past max_len refused (NERVE_TOO_LONG) */
  uint64_t answered; /* requests its service answered */
  uint64_t replies;  /* answers its client took, right */
  uint64_t wrong;    /* answers its client took, wrong */
  uint64_t waited;   /* right answers of nerve_call_wait */
  uint64_t failed;   /* calls that ended without an answer */
  uint64_t seq_answered; /* requests its sequence service answered */
  uint64_t seq_refused;  /* answers past its max_len refused (NERVE_TOO_LONG) */
  uint64_t seq_replies;  /* sequence answers its client took, right */
  uint64_t seq_wrong;    /* sequence answers its client took, wrong */
  uint64_t seq_largest;  /* the most elements of one of them */
} report;
static const nerve_field report_fields[] = {
    NERVE_FIELD(report, received, NERVE_U64), NERVE_FIELD(report, largest, NERVE_U64),
    NERVE_FIELD(report, bad, NERVE_U64),      NERVE_FIELD(report, refused, NERVE_U64),
    NERVE_FIELD(report, answered, NERVE_U64), NERVE_FIELD(report, replies, NERVE_U64),
    NERVE_FIELD(report, wrong, NERVE_U64),    NERVE_FIELD(report, waited, NERVE_U64),
    NERVE_FIELD(report, failed, NERVE_U64),   NERVE_FIELD(report, seq_answered, NERVE_U64),
    NERVE_FIELD(report, seq_refused, NERVE_U64), NERVE_FIELD(report, seq_replies, NERVE_U64),
    NERVE_FIELD(report, seq_wrong, NERVE_U64), NERVE_FIELD(report, seq_largest, NERVE_U64)};
static const nerve_type report_type = NERVE_TYPE(report, "ctest::Report", report_fields);

static const nerve_type tick_type = NERVE_BUILTIN(nerve_Tick);
static const nerve_type scalar_type = NERVE_BUILTIN(nerve_Scalar);

#define MAX_DETS 1000
#define MAX_PATH 500
static const size_t LENGTHS[4] = {0, 1, 400, 401};

typedef struct {
  nerve_port dets, dets_in, rep, plan, planner, plan_seq, planner_seq;
  uint64_t n;         /* steps */
  uint64_t in_flight; /* calls of nerve_call not taken yet */
  uint64_t seq_in_flight; /* sequence calls not taken yet */
  report r;
} agent;

static int fail(const char *what) {
  fprintf(stderr, "cseq: %s: %s\n", what, nerve_last_error());
  return 1;
}

static int cseq_init(nerve_setup *setup, void *user) {
  agent *a = user;
  if (nerve_setup_output_seq(setup, "dets", &detection_type, &header_type, MAX_DETS, &a->dets) != NERVE_OK) {
    return fail("output_seq dets");
  }
  if (nerve_setup_input_seq(setup, "dets_in", &detection_type, &header_type, &a->dets_in) != NERVE_OK) {
    return fail("input_seq dets_in");
  }
  if (nerve_setup_output_type(setup, "report", &report_type, &a->rep) != NERVE_OK) {
    return fail("output report");
  }
  if (nerve_setup_serve(setup, "plan", &tick_type, &scalar_type, &a->plan) != NERVE_OK) {
    return fail("serve plan");
  }
  if (nerve_setup_client(setup, "planner", &tick_type, &scalar_type, 300000000, &a->planner) != NERVE_OK) {
    return fail("client planner");
  }
  if (nerve_setup_serve_seq(setup, "plan_seq", &tick_type, &scalar_type, &tick_type, MAX_PATH, &a->plan_seq) !=
      NERVE_OK) {
    return fail("serve_seq plan_seq");
  }
  if (nerve_setup_client_seq(setup, "planner_seq", &tick_type, &scalar_type, &tick_type, 300000000, &a->planner_seq) !=
      NERVE_OK) {
    return fail("client_seq planner_seq");
  }
  return 0;
}

/* The sequence service's answer: the request as header, then seq scalars
 * 0, 1, ... stamped with the request's stamp, written in place. */
static int answer_path(const void *request, nerve_answer *answer, void *user) {
  const nerve_Tick *t = request;
  agent *a = user;
  nerve_seq_loan l;
  nerve_status st = nerve_answer_loan(answer, (size_t)t->seq, &l);
  if (st == NERVE_TOO_LONG) { /* past max_len: its caller is told so */
    a->r.seq_refused++;
    return 0;
  }
  if (st != NERVE_OK) {
    return fail("answer_loan plan_seq");
  }
  *(nerve_Tick *)l.header = *t;
  nerve_Scalar *items = l.items;
  for (size_t i = 0; i < l.len; i++) {
    items[i].value = (double)i;
    items[i].stamp_ns = t->stamp_ns;
  }
  a->r.seq_answered++;
  return 0;
}

/* Takes the sequence client's answers, read in place and checked, and keeps one call in flight. */
static int call_path(nerve_ctx *ctx, agent *a) {
  for (;;) {
    nerve_seq s;
    uint64_t id = 0;
    nerve_status st = nerve_call_take_seq(ctx, a->planner_seq, &id, &s);
    if (st == NERVE_NO_SAMPLE || st == NERVE_NOT_IN_HARNESS) {
      break;
    }
    a->seq_in_flight--;
    if (st == NERVE_CALL_FAILED) {
      a->r.failed++;
      continue;
    }
    if (st != NERVE_OK) {
      return fail("call_take_seq planner_seq");
    }
    const nerve_Tick *h = s.header;
    const nerve_Scalar *items = s.items;
    int right = h != NULL && h->seq == s.len;
    for (size_t i = 0; right && i < s.len; i++) {
      right = items[i].value == (double)i && items[i].stamp_ns == h->stamp_ns;
    }
    if (right) {
      a->r.seq_replies++;
      if (s.len > a->r.seq_largest) {
        a->r.seq_largest = s.len;
      }
    } else {
      a->r.seq_wrong++;
    }
  }
  if (a->seq_in_flight == 0) {
    nerve_Tick t = {(a->n * 37) % 400, a->n};
    uint64_t id = 0;
    nerve_status st = nerve_call(ctx, a->planner_seq, &t, sizeof t, &id);
    if (st == NERVE_OK) {
      a->seq_in_flight++;
    } else if (st != NERVE_CALL_FAILED && st != NERVE_NOT_IN_HARNESS) {
      return fail("call planner_seq");
    }
  }
  return 0;
}

/* The service's answer: twice the request's seq, its stamp kept. */
static int answer_plan(const void *request, void *answer, void *user) {
  const nerve_Tick *t = request;
  nerve_Scalar *s = answer;
  agent *a = user;
  s->value = 2.0 * (double)t->seq;
  s->stamp_ns = t->stamp_ns;
  a->r.answered++;
  return 0;
}

/* Reads every sequence waiting on dets_in, in place, and checks it. */
static int read_dets(nerve_ctx *ctx, agent *a) {
  for (;;) {
    nerve_seq s;
    nerve_status st = nerve_take_seq(ctx, a->dets_in, &s);
    if (st == NERVE_NO_SAMPLE) {
      return 0;
    }
    if (st != NERVE_OK) {
      return fail("take_seq dets_in");
    }
    const detections_header *h = s.header;
    const detection *d = s.items;
    a->r.received++;
    if (s.len > a->r.largest) {
      a->r.largest = s.len;
    }
    int right = h->count == s.len;
    for (size_t j = 0; right && j < s.len; j++) {
      right = d[j].id == j && d[j].y == (float)h->frame;
    }
    if (!right) {
      a->r.bad++;
    }
  }
}

/* Sends this step's detections, written in place, and tries one past the maximum. */
static int send_dets(nerve_ctx *ctx, agent *a) {
  size_t len = LENGTHS[(a->n - 1) % 4];
  nerve_seq_loan l;
  if (nerve_loan_seq(ctx, a->dets, len, &l) != NERVE_OK) {
    return fail("loan_seq dets");
  }
  detections_header *h = l.header;
  detection *d = l.items;
  h->frame = a->n;
  h->count = (uint32_t)len;
  for (size_t j = 0; j < l.len; j++) {
    d[j].x = (float)j;
    d[j].y = (float)a->n;
    d[j].id = (uint32_t)j;
  }
  if (nerve_send(ctx, a->dets) != NERVE_OK) {
    return fail("send dets");
  }
  nerve_status st = nerve_loan_seq(ctx, a->dets, MAX_DETS + 1, &l);
  if (st != NERVE_TOO_LONG || l.header != NULL || l.items != NULL) {
    fprintf(stderr, "cseq: a loan past max_len was not refused (%d)\n", (int)st);
    return 1;
  }
  a->r.refused++;
  return 0;
}

/* Checks one answer of the client: its value is twice its stamp (the request's seq). */
static void check_answer(agent *a, const nerve_Scalar *s, uint64_t *right) {
  if (s->value == 2.0 * (double)s->stamp_ns) {
    (*right)++;
  } else {
    a->r.wrong++;
  }
}

static int call_plan(nerve_ctx *ctx, agent *a) {
  nerve_Scalar s;
  uint64_t id = 0;
  for (;;) {
    nerve_status st = nerve_call_take(ctx, a->planner, &id, &s, sizeof s);
    if (st == NERVE_NO_SAMPLE) {
      break;
    }
    if (st == NERVE_NOT_IN_HARNESS) { /* a test harness carries no calls */
      return 0;
    }
    a->in_flight--;
    if (st == NERVE_OK) {
      check_answer(a, &s, &a->r.replies);
    } else if (st == NERVE_CALL_FAILED) {
      a->r.failed++;
    } else {
      return fail("call_take planner");
    }
  }
  nerve_Tick t = {a->n, a->n};
  if (a->in_flight == 0) {
    nerve_status st = nerve_call(ctx, a->planner, &t, sizeof t, &id);
    if (st == NERVE_OK) {
      a->in_flight++;
    } else if (st != NERVE_CALL_FAILED) { /* not wired yet, or no server: tried again next step */
      return fail("call planner");
    }
  }
  /* once in ten steps, when answers come: a call that waits in the step */
  if (a->n % 10 == 0 && a->r.replies > 0) {
    nerve_Tick w = {a->n + 1000000, a->n + 1000000};
    nerve_status st = nerve_call_wait(ctx, a->planner, &w, sizeof w, &s, sizeof s);
    if (st == NERVE_OK) {
      check_answer(a, &s, &a->r.waited);
    } else if (st == NERVE_CALL_FAILED) {
      a->r.failed++;
    } else {
      return fail("call_wait planner");
    }
  }
  return 0;
}

static int cseq_step(nerve_ctx *ctx, void *user) {
  agent *a = user;
  a->n++;
  if (read_dets(ctx, a) || send_dets(ctx, a)) {
    return 1;
  }
  size_t answered = 0;
  nerve_status st = nerve_serve(ctx, a->plan, answer_plan, a, &answered);
  if (st != NERVE_OK && st != NERVE_NOT_IN_HARNESS) {
    return fail("serve plan");
  }
  st = nerve_serve_seq(ctx, a->plan_seq, answer_path, a, &answered);
  if (st != NERVE_OK && st != NERVE_NOT_IN_HARNESS && st != NERVE_TOO_LONG) {
    return fail("serve_seq plan_seq");
  }
  if (call_plan(ctx, a) || call_path(ctx, a)) {
    return 1;
  }
  void *slot = NULL;
  if (nerve_loan(ctx, a->rep, &slot) != NERVE_OK) {
    return fail("loan report");
  }
  *(report *)slot = a->r;
  return nerve_send(ctx, a->rep) == NERVE_OK ? 0 : fail("send report");
}

static const nerve_agent_vtable cseq_agent = {
    .kind = "cseq",
    .period_ns = 20000000,
    .init = cseq_init,
    .start = NULL,
    .step = cseq_step,
    .stop = NULL,
};

#ifndef NERVE_NO_MAIN
int main(int argc, char **argv) {
  static agent a;
  return nerve_run(argc, argv, &cseq_agent, &a);
}
#endif
