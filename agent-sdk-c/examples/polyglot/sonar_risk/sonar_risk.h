/* sonar_risk.h: a sonar risk estimator, a plain C library that knows
 * nothing of nerve (no nerve header, no nerve type). It stands for the C
 * code a team already has: issue 43's "real port" turns it into a nerve
 * agent with glue alone (../risk.c).
 *
 * A ring of range readings, each at a bearing, becomes one risk in [0, 1]:
 * how close the nearest obstacle ahead is, weighted by how far it is from
 * straight ahead. */
#ifndef SONAR_RISK_H
#define SONAR_RISK_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* How the estimator weighs a reading. */
typedef struct sonar_risk_params {
  double safe_range_m;   /* at or beyond this range a reading is no risk */
  double stop_range_m;   /* at or under this range a reading is full risk */
  double half_width_rad; /* readings further than this from ahead are ignored */
} sonar_risk_params;

/* The defaults for a small indoor robot: safe at 1.2 m, stop at 0.25 m,
 * looking 75 degrees either side of ahead. */
sonar_risk_params sonar_risk_default_params(void);

/* The risk of `n` readings: `ranges_m[i]` at bearing `bearings_rad[i]`
 * (0 ahead, counter-clockwise positive), `valid[i]` non-zero when reading
 * i is one (a sensor that saw nothing has none). Returns a value in
 * [0, 1]; 0 when no valid reading is within the width. Writes the index of
 * the reading that set it to `*worst` when `worst` is not NULL (or n). */
double sonar_risk(const sonar_risk_params *p, const float *ranges_m, const double *bearings_rad,
                  const unsigned char *valid, size_t n, size_t *worst);

#ifdef __cplusplus
}
#endif

#endif
