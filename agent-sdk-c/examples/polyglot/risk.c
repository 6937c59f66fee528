/* risk.c: the glue that makes the plain C library sonar_risk (which knows
 * nothing of nerve) a nerve agent. It reads each nerve::SonarScan of input
 * `scan` in place, hands the ring to sonar_risk(), and publishes the result
 * as a nerve::Scalar on output `risk`. Everything nerve-specific of the port
 * is in this file; the library is unchanged. */
#include "nerve.h"
#include "nerve_types.h"
#include "sonar_risk/sonar_risk.h"

#include <stdio.h>

typedef struct {
  nerve_port scan;
  nerve_port risk;
  sonar_risk_params params;
  double bearings_rad[12]; /* sonar i points i * 30 degrees counter-clockwise of ahead */
} risk_agent;

static int fail(const char *what) {
  fprintf(stderr, "crisk: %s: %s\n", what, nerve_last_error());
  return 1;
}

static int risk_init(nerve_setup *setup, void *user) {
  risk_agent *a = user;
  a->params = sonar_risk_default_params();
  for (int i = 0; i < 12; i++) {
    double deg = i <= 6 ? 30.0 * i : 30.0 * i - 360.0; /* -180..180: right is negative */
    a->bearings_rad[i] = deg * 3.14159265358979323846 / 180.0;
  }
  if (NERVE_SETUP_INPUT(setup, "scan", nerve_SonarScan, &a->scan) != NERVE_OK) {
    return fail("input scan");
  }
  if (NERVE_SETUP_OUTPUT(setup, "risk", nerve_Scalar, &a->risk) != NERVE_OK) {
    return fail("output risk");
  }
  return 0;
}

static int risk_step(nerve_ctx *ctx, void *user) {
  risk_agent *a = user;
  const void *data = NULL;
  size_t len = 0;
  /* only the newest scan matters */
  nerve_status s = nerve_latest(ctx, a->scan, &data, &len);
  if (s == NERVE_NO_SAMPLE) {
    return 0;
  }
  if (s != NERVE_OK || len != sizeof(nerve_SonarScan)) {
    return fail("latest scan");
  }
  const nerve_SonarScan *scan = data;
  double r = sonar_risk(&a->params, scan->ranges_m, a->bearings_rad, scan->valid, 12, NULL);
  void *slot = NULL;
  if (nerve_loan(ctx, a->risk, &slot) != NERVE_OK) {
    return fail("loan");
  }
  nerve_Scalar *out = slot;
  out->value = r;
  out->stamp_ns = scan->stamp_ns;
  return nerve_send(ctx, a->risk) == NERVE_OK ? 0 : fail("send");
}

int main(int argc, char **argv) {
  static risk_agent a;
  nerve_agent_vtable agent = {.kind = "crisk", .period_ns = 0, .init = risk_init, .step = risk_step};
  return nerve_run(argc, argv, &agent, &a);
}
