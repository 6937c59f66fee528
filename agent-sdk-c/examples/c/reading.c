/* reading.c: a C agent with a payload type of its own, lab::Reading,
 * declared to nerve by a NERVE_FIELD table so that the router can check it
 * against any other agent's lab::Reading (Rust, Python or C): ports of the
 * same type name connect only when their layouts agree.
 *
 * Every 20 ms it sends a Reading on `out` (`value` the cycle, `id` how
 * many Readings it has taken from `in` so far). Built with
 * -DREADING_DRIFT it lays lab::Reading out otherwise (a field renamed and
 * retyped, as an old copy of the struct would): the router then refuses to
 * connect it to the first layout, naming both. READING_TYPE_NAME renames
 * the type (below). */
#include "nerve.h"
#include "nerve_types.h"

#include <stdint.h>
#include <stdio.h>

#ifndef READING_DRIFT
typedef struct {
  double value;
  uint32_t id;
  float samples[3];
} reading;

static const nerve_field reading_fields[] = {
    NERVE_FIELD(reading, value, NERVE_F64),
    NERVE_FIELD(reading, id, NERVE_U32),
    NERVE_FIELD_ARRAY(reading, samples, NERVE_F32),
};
#else
typedef struct {
  double value;
  uint32_t id;
  uint32_t flags;
  float samples[2];
} reading;

static const nerve_field reading_fields[] = {
    NERVE_FIELD(reading, value, NERVE_F64),
    NERVE_FIELD(reading, id, NERVE_U32),
    NERVE_FIELD(reading, flags, NERVE_U32),
    NERVE_FIELD_ARRAY(reading, samples, NERVE_F32),
};
#endif

/* The type's name; -DREADING_TYPE_NAME='"acme::Gripper"' gives this layout
 * the name of a Rust agent's type (tests/src/bin/gripper.rs), which the
 * router must then refuse to connect to that agent, naming both. */
#ifndef READING_TYPE_NAME
#define READING_TYPE_NAME "lab::Reading"
#endif
static const nerve_type reading_type = NERVE_TYPE(reading, READING_TYPE_NAME, reading_fields);

typedef struct {
  nerve_port in;
  nerve_port out;
  uint32_t taken;
} state;

static int fail(const char *what) {
  fprintf(stderr, "creading: %s: %s\n", what, nerve_last_error());
  return 1;
}

static int reading_init(nerve_setup *setup, void *user) {
  state *s = user;
  if (nerve_setup_input_type(setup, "in", &reading_type, &s->in) != NERVE_OK) {
    return fail("input in");
  }
  if (nerve_setup_output_type(setup, "out", &reading_type, &s->out) != NERVE_OK) {
    return fail("output out");
  }
  return 0;
}

static int reading_step(nerve_ctx *ctx, void *user) {
  state *s = user;
  const void *data = NULL;
  size_t len = 0;
  nerve_status st;
  while ((st = nerve_take(ctx, s->in, &data, &len)) == NERVE_OK) {
    s->taken++;
  }
  if (st != NERVE_NO_SAMPLE) {
    return fail("take");
  }
  uint64_t cycle = 0;
  void *slot = NULL;
  if (nerve_cycle(ctx, &cycle) != NERVE_OK || nerve_loan(ctx, s->out, &slot) != NERVE_OK) {
    return fail("cycle or loan");
  }
  reading *r = slot;
  r->value = (double)cycle;
  r->id = s->taken;
  r->samples[0] = 1.5f;
  return nerve_send(ctx, s->out) == NERVE_OK ? 0 : fail("send");
}

int main(int argc, char **argv) {
  static state s;
  nerve_agent_vtable agent = {
      .kind = "creading",
      .period_ns = 20000000,
      .init = reading_init,
      .start = NULL,
      .step = reading_step,
      .stop = NULL,
  };
  return nerve_run(argc, argv, &agent, &s);
}
