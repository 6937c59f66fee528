/* sonar_risk.c: see sonar_risk.h. Plain C99, no allocation, no globals. */
#include "sonar_risk.h"

#include <math.h>

sonar_risk_params sonar_risk_default_params(void) {
  sonar_risk_params p;
  p.safe_range_m = 1.2;
  p.stop_range_m = 0.25;
  p.half_width_rad = 75.0 * 3.14159265358979323846 / 180.0;
  return p;
}

/* 1 at or under stop, 0 at or beyond safe, linear between. */
static double range_risk(const sonar_risk_params *p, double r) {
  if (!(r > p->stop_range_m)) { /* also NaN: unknown is treated as close */
    return 1.0;
  }
  if (r >= p->safe_range_m) {
    return 0.0;
  }
  return (p->safe_range_m - r) / (p->safe_range_m - p->stop_range_m);
}

double sonar_risk(const sonar_risk_params *p, const float *ranges_m, const double *bearings_rad,
                  const unsigned char *valid, size_t n, size_t *worst) {
  double risk = 0.0;
  size_t at = n;
  for (size_t i = 0; i < n; i++) {
    if (!valid[i]) {
      continue;
    }
    double off = fabs(bearings_rad[i]);
    if (off > p->half_width_rad) {
      continue;
    }
    /* straight ahead counts fully, the edge of the width half */
    double weight = 1.0 - 0.5 * off / p->half_width_rad;
    double r = weight * range_risk(p, ranges_m[i]);
    if (r > risk) {
      risk = r;
      at = i;
    }
  }
  if (worst) {
    *worst = at;
  }
  return risk;
}
