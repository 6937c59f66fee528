/* nerve_types.h: the built-in payload types of nerve as C structs.
 * Generated from their schemas (shm-schemas) by agent-sdk-c/tests/types_header.rs:
 * do not edit; regenerate with
 * NERVE_BLESS=1 cargo nextest run -p nerve-agent-c -E 'test(types_header)'.
 *
 * For each type T (nerve::Tick is nerve_Tick): the struct, T_TYPE_NAME
 * ("nerve::Tick") and T_FINGERPRINT (its layout's fingerprint, as nerve
 * checks it), and static asserts that this compiler lays it out as nerve
 * does. Declare a port with NERVE_SETUP_INPUT(setup, "in", nerve_Tick, &port)
 * (and NERVE_SETUP_OUTPUT): the type's name, size, alignment and fingerprint
 * are passed for nerve to check. NERVE_BUILTIN_PAYLOADS(X) calls X(T) for
 * every type. Valid C11 and C++17. */
#ifndef NERVE_TYPES_H
#define NERVE_TYPES_H

#include <stddef.h>
#include <stdint.h>
#ifndef __cplusplus
#include <stdbool.h>
#endif

#ifdef __cplusplus
#define NERVE_STATIC_ASSERT(cond, msg) static_assert(cond, msg)
#define NERVE_ALIGNOF(T) alignof(T)
#else
#define NERVE_STATIC_ASSERT(cond, msg) _Static_assert(cond, msg)
#define NERVE_ALIGNOF(T) _Alignof(T)
#endif

/* Declares input NAME of payload struct T on SETUP (in `init`), handle in *PORT. */
#define NERVE_SETUP_INPUT(setup, name, T, port) \
  nerve_setup_input((setup), (name), T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), T##_FINGERPRINT, (port))
/* Declares output NAME of payload struct T on SETUP (in `init`), handle in *PORT. */
#define NERVE_SETUP_OUTPUT(setup, name, T, port) \
  nerve_setup_output((setup), (name), T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), T##_FINGERPRINT, (port))

/* Your own payload struct S, for nerve_setup_input_type/nerve_setup_output_type:
 *   static const nerve_field reading_fields[] = {
 *       NERVE_FIELD(reading, value, NERVE_F64), NERVE_FIELD_ARRAY(reading, samples, NERVE_F32)};
 *   static const nerve_type reading_type = NERVE_TYPE(reading, "lab::Reading", reading_fields);
 * Field names, types and order as the Rust or Python type of that name has them. */
#define NERVE_FIELD(S, field, primitive) {#field, (primitive), offsetof(S, field), 0}
#define NERVE_FIELD_ARRAY(S, field, primitive) \
  {#field, (primitive), offsetof(S, field), sizeof(((S *)0)->field) / sizeof(((S *)0)->field[0])}
#define NERVE_TYPE(S, name, fields) {(name), sizeof(S), NERVE_ALIGNOF(S), (fields), sizeof(fields) / sizeof((fields)[0])}

/* A built-in payload struct T of this header as a nerve_type, for the parts of a
 * sequence or a call (nerve_setup_output_seq, nerve_setup_serve):
 *   static const nerve_type tick_type = NERVE_BUILTIN(nerve_Tick);
 * and a primitive by its Rust name: NERVE_BUILTIN_PRIMITIVE(uint8_t, "u8"). */
#define NERVE_BUILTIN(T) {T##_TYPE_NAME, sizeof(T), NERVE_ALIGNOF(T), NULL, 0}
#define NERVE_BUILTIN_PRIMITIVE(C, name) {(name), sizeof(C), NERVE_ALIGNOF(C), NULL, 0}

/* nerve::Tick */
typedef struct nerve_Tick {
  uint64_t seq;
  uint64_t stamp_ns;
} nerve_Tick;
NERVE_STATIC_ASSERT(sizeof(nerve_Tick) == 16, "nerve::Tick is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_Tick) == 8, "nerve::Tick is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_Tick, seq) == 0, "nerve::Tick.seq is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_Tick, stamp_ns) == 8, "nerve::Tick.stamp_ns is at byte 8");

#define nerve_Tick_TYPE_NAME "nerve::Tick"
#define nerve_Tick_FINGERPRINT UINT64_C(0xcbc6bcae854450d0)
#define NERVE_TICK_FINGERPRINT nerve_Tick_FINGERPRINT

/* nerve::RouterEpoch */
typedef struct nerve_RouterEpoch {
  uint64_t epoch;
  uint32_t pid;
  uint32_t reserved;
} nerve_RouterEpoch;
NERVE_STATIC_ASSERT(sizeof(nerve_RouterEpoch) == 16, "nerve::RouterEpoch is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_RouterEpoch) == 8, "nerve::RouterEpoch is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_RouterEpoch, epoch) == 0, "nerve::RouterEpoch.epoch is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_RouterEpoch, pid) == 8, "nerve::RouterEpoch.pid is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_RouterEpoch, reserved) == 12, "nerve::RouterEpoch.reserved is at byte 12");

#define nerve_RouterEpoch_TYPE_NAME "nerve::RouterEpoch"
#define nerve_RouterEpoch_FINGERPRINT UINT64_C(0xf2cf53aaf3baeedb)
#define NERVE_ROUTER_EPOCH_FINGERPRINT nerve_RouterEpoch_FINGERPRINT

/* nerve::Scalar */
typedef struct nerve_Scalar {
  double value;
  uint64_t stamp_ns;
} nerve_Scalar;
NERVE_STATIC_ASSERT(sizeof(nerve_Scalar) == 16, "nerve::Scalar is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_Scalar) == 8, "nerve::Scalar is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_Scalar, value) == 0, "nerve::Scalar.value is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_Scalar, stamp_ns) == 8, "nerve::Scalar.stamp_ns is at byte 8");

#define nerve_Scalar_TYPE_NAME "nerve::Scalar"
#define nerve_Scalar_FINGERPRINT UINT64_C(0x00c0d0b2b30912c6)
#define NERVE_SCALAR_FINGERPRINT nerve_Scalar_FINGERPRINT

/* A UTF-8 string of at most 32 bytes: `len`, then the bytes (not NUL-terminated). */
typedef struct nerve_FixedName {
  uint32_t len;
  uint8_t bytes[32];
} nerve_FixedName;
NERVE_STATIC_ASSERT(sizeof(nerve_FixedName) == 36, "nerve::FixedName is 36 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_FixedName) == 4, "nerve::FixedName is aligned to 4 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_FixedName, len) == 0, "nerve::FixedName.len is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_FixedName, bytes) == 4, "nerve::FixedName.bytes is at byte 4");

/* nerve::RingNotice */
typedef struct nerve_RingNotice {
  nerve_FixedName ring;
  uint32_t slot;
  uint64_t ring_id;
  uint64_t seq;
  uint64_t stamp_ns;
  uint64_t size;
  uint32_t width;
  uint32_t height;
  uint32_t format;
  uint32_t reserved;
  uint64_t creation_id;
} nerve_RingNotice;
NERVE_STATIC_ASSERT(sizeof(nerve_RingNotice) == 96, "nerve::RingNotice is 96 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_RingNotice) == 8, "nerve::RingNotice is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, ring) == 0, "nerve::RingNotice.ring is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, slot) == 36, "nerve::RingNotice.slot is at byte 36");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, ring_id) == 40, "nerve::RingNotice.ring_id is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, seq) == 48, "nerve::RingNotice.seq is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, stamp_ns) == 56, "nerve::RingNotice.stamp_ns is at byte 56");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, size) == 64, "nerve::RingNotice.size is at byte 64");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, width) == 72, "nerve::RingNotice.width is at byte 72");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, height) == 76, "nerve::RingNotice.height is at byte 76");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, format) == 80, "nerve::RingNotice.format is at byte 80");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, reserved) == 84, "nerve::RingNotice.reserved is at byte 84");
NERVE_STATIC_ASSERT(offsetof(nerve_RingNotice, creation_id) == 88, "nerve::RingNotice.creation_id is at byte 88");

#define nerve_RingNotice_TYPE_NAME "nerve::RingNotice"
#define nerve_RingNotice_FINGERPRINT UINT64_C(0xd296b2875496519c)
#define NERVE_RING_NOTICE_FINGERPRINT nerve_RingNotice_FINGERPRINT

/* nerve::SonarScan */
typedef struct nerve_SonarScan {
  uint64_t seq;
  uint64_t stamp_ns;
  float ranges_m[12];
  float risk[12];
  uint8_t valid[12];
  uint8_t reserved[4];
} nerve_SonarScan;
NERVE_STATIC_ASSERT(sizeof(nerve_SonarScan) == 128, "nerve::SonarScan is 128 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_SonarScan) == 8, "nerve::SonarScan is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, seq) == 0, "nerve::SonarScan.seq is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, stamp_ns) == 8, "nerve::SonarScan.stamp_ns is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, ranges_m) == 16, "nerve::SonarScan.ranges_m is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, risk) == 64, "nerve::SonarScan.risk is at byte 64");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, valid) == 112, "nerve::SonarScan.valid is at byte 112");
NERVE_STATIC_ASSERT(offsetof(nerve_SonarScan, reserved) == 124, "nerve::SonarScan.reserved is at byte 124");

#define nerve_SonarScan_TYPE_NAME "nerve::SonarScan"
#define nerve_SonarScan_FINGERPRINT UINT64_C(0x2a288f1651fe8835)
#define NERVE_SONAR_SCAN_FINGERPRINT nerve_SonarScan_FINGERPRINT

/* nerve::VelocityCommand */
typedef struct nerve_VelocityCommand {
  double v;
  double omega;
  uint64_t stamp_ns;
} nerve_VelocityCommand;
NERVE_STATIC_ASSERT(sizeof(nerve_VelocityCommand) == 24, "nerve::VelocityCommand is 24 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_VelocityCommand) == 8, "nerve::VelocityCommand is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_VelocityCommand, v) == 0, "nerve::VelocityCommand.v is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_VelocityCommand, omega) == 8, "nerve::VelocityCommand.omega is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_VelocityCommand, stamp_ns) == 16, "nerve::VelocityCommand.stamp_ns is at byte 16");

#define nerve_VelocityCommand_TYPE_NAME "nerve::VelocityCommand"
#define nerve_VelocityCommand_FINGERPRINT UINT64_C(0xa6c0cee2850e2425)
#define NERVE_VELOCITY_COMMAND_FINGERPRINT nerve_VelocityCommand_FINGERPRINT

/* nerve::LinguisticCommand */
typedef struct nerve_LinguisticCommand {
  uint32_t term;
  float intensity;
  uint64_t stamp_ns;
} nerve_LinguisticCommand;
NERVE_STATIC_ASSERT(sizeof(nerve_LinguisticCommand) == 16, "nerve::LinguisticCommand is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_LinguisticCommand) == 8, "nerve::LinguisticCommand is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_LinguisticCommand, term) == 0, "nerve::LinguisticCommand.term is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_LinguisticCommand, intensity) == 4, "nerve::LinguisticCommand.intensity is at byte 4");
NERVE_STATIC_ASSERT(offsetof(nerve_LinguisticCommand, stamp_ns) == 8, "nerve::LinguisticCommand.stamp_ns is at byte 8");

#define nerve_LinguisticCommand_TYPE_NAME "nerve::LinguisticCommand"
#define nerve_LinguisticCommand_FINGERPRINT UINT64_C(0xc1884e78bba92d1a)
#define NERVE_LINGUISTIC_COMMAND_FINGERPRINT nerve_LinguisticCommand_FINGERPRINT

/* nerve::SafetyStop */
typedef struct nerve_SafetyStop {
  uint8_t active;
  uint8_t allow_turn;
  uint8_t reserved[2];
  uint32_t hold_ms;
  uint64_t stamp_ns;
} nerve_SafetyStop;
NERVE_STATIC_ASSERT(sizeof(nerve_SafetyStop) == 16, "nerve::SafetyStop is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_SafetyStop) == 8, "nerve::SafetyStop is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_SafetyStop, active) == 0, "nerve::SafetyStop.active is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_SafetyStop, allow_turn) == 1, "nerve::SafetyStop.allow_turn is at byte 1");
NERVE_STATIC_ASSERT(offsetof(nerve_SafetyStop, reserved) == 2, "nerve::SafetyStop.reserved is at byte 2");
NERVE_STATIC_ASSERT(offsetof(nerve_SafetyStop, hold_ms) == 4, "nerve::SafetyStop.hold_ms is at byte 4");
NERVE_STATIC_ASSERT(offsetof(nerve_SafetyStop, stamp_ns) == 8, "nerve::SafetyStop.stamp_ns is at byte 8");

#define nerve_SafetyStop_TYPE_NAME "nerve::SafetyStop"
#define nerve_SafetyStop_FINGERPRINT UINT64_C(0x4689caec41706bb0)
#define NERVE_SAFETY_STOP_FINGERPRINT nerve_SafetyStop_FINGERPRINT

/* nerve::Odometry */
typedef struct nerve_Odometry {
  double x;
  double y;
  double theta;
  double v;
  double omega;
  uint64_t stamp_ns;
} nerve_Odometry;
NERVE_STATIC_ASSERT(sizeof(nerve_Odometry) == 48, "nerve::Odometry is 48 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_Odometry) == 8, "nerve::Odometry is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, x) == 0, "nerve::Odometry.x is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, y) == 8, "nerve::Odometry.y is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, theta) == 16, "nerve::Odometry.theta is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, v) == 24, "nerve::Odometry.v is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, omega) == 32, "nerve::Odometry.omega is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_Odometry, stamp_ns) == 40, "nerve::Odometry.stamp_ns is at byte 40");

#define nerve_Odometry_TYPE_NAME "nerve::Odometry"
#define nerve_Odometry_FINGERPRINT UINT64_C(0xa3ab8241ba85ea50)
#define NERVE_ODOMETRY_FINGERPRINT nerve_Odometry_FINGERPRINT

/* nerve::GroundTruth */
typedef struct nerve_GroundTruth {
  double sim_time;
  double x;
  double y;
  double theta;
  double v;
  double omega;
  uint64_t collisions;
  uint8_t in_contact;
  uint8_t reserved[7];
  uint64_t stamp_ns;
} nerve_GroundTruth;
NERVE_STATIC_ASSERT(sizeof(nerve_GroundTruth) == 72, "nerve::GroundTruth is 72 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_GroundTruth) == 8, "nerve::GroundTruth is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, sim_time) == 0, "nerve::GroundTruth.sim_time is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, x) == 8, "nerve::GroundTruth.x is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, y) == 16, "nerve::GroundTruth.y is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, theta) == 24, "nerve::GroundTruth.theta is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, v) == 32, "nerve::GroundTruth.v is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, omega) == 40, "nerve::GroundTruth.omega is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, collisions) == 48, "nerve::GroundTruth.collisions is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, in_contact) == 56, "nerve::GroundTruth.in_contact is at byte 56");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, reserved) == 57, "nerve::GroundTruth.reserved is at byte 57");
NERVE_STATIC_ASSERT(offsetof(nerve_GroundTruth, stamp_ns) == 64, "nerve::GroundTruth.stamp_ns is at byte 64");

#define nerve_GroundTruth_TYPE_NAME "nerve::GroundTruth"
#define nerve_GroundTruth_FINGERPRINT UINT64_C(0xa93e0d0dfa762451)
#define NERVE_GROUND_TRUTH_FINGERPRINT nerve_GroundTruth_FINGERPRINT

/* nerve::IrSighting */
typedef struct nerve_IrSighting {
  uint64_t seq;
  uint64_t stamp_ns;
  uint8_t seen;
  uint8_t checkpoint_id;
  uint8_t transmitters;
  uint8_t reserved[5];
} nerve_IrSighting;
NERVE_STATIC_ASSERT(sizeof(nerve_IrSighting) == 24, "nerve::IrSighting is 24 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_IrSighting) == 8, "nerve::IrSighting is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, seq) == 0, "nerve::IrSighting.seq is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, stamp_ns) == 8, "nerve::IrSighting.stamp_ns is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, seen) == 16, "nerve::IrSighting.seen is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, checkpoint_id) == 17, "nerve::IrSighting.checkpoint_id is at byte 17");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, transmitters) == 18, "nerve::IrSighting.transmitters is at byte 18");
NERVE_STATIC_ASSERT(offsetof(nerve_IrSighting, reserved) == 19, "nerve::IrSighting.reserved is at byte 19");

#define nerve_IrSighting_TYPE_NAME "nerve::IrSighting"
#define nerve_IrSighting_FINGERPRINT UINT64_C(0x93ebbba7a7c03fac)
#define NERVE_IR_SIGHTING_FINGERPRINT nerve_IrSighting_FINGERPRINT

/* nerve::HeadCommand */
typedef struct nerve_HeadCommand {
  double pan_rad;
  double tilt_rad;
  uint64_t stamp_ns;
} nerve_HeadCommand;
NERVE_STATIC_ASSERT(sizeof(nerve_HeadCommand) == 24, "nerve::HeadCommand is 24 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_HeadCommand) == 8, "nerve::HeadCommand is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadCommand, pan_rad) == 0, "nerve::HeadCommand.pan_rad is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadCommand, tilt_rad) == 8, "nerve::HeadCommand.tilt_rad is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadCommand, stamp_ns) == 16, "nerve::HeadCommand.stamp_ns is at byte 16");

#define nerve_HeadCommand_TYPE_NAME "nerve::HeadCommand"
#define nerve_HeadCommand_FINGERPRINT UINT64_C(0xcef3f56f89a0435d)
#define NERVE_HEAD_COMMAND_FINGERPRINT nerve_HeadCommand_FINGERPRINT

/* nerve::HeadState */
typedef struct nerve_HeadState {
  double pan_rad;
  double tilt_rad;
  double target_pan_rad;
  double target_tilt_rad;
  uint64_t stamp_ns;
} nerve_HeadState;
NERVE_STATIC_ASSERT(sizeof(nerve_HeadState) == 40, "nerve::HeadState is 40 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_HeadState) == 8, "nerve::HeadState is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadState, pan_rad) == 0, "nerve::HeadState.pan_rad is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadState, tilt_rad) == 8, "nerve::HeadState.tilt_rad is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadState, target_pan_rad) == 16, "nerve::HeadState.target_pan_rad is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadState, target_tilt_rad) == 24, "nerve::HeadState.target_tilt_rad is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_HeadState, stamp_ns) == 32, "nerve::HeadState.stamp_ns is at byte 32");

#define nerve_HeadState_TYPE_NAME "nerve::HeadState"
#define nerve_HeadState_FINGERPRINT UINT64_C(0x2bce2ca9637af5b5)
#define NERVE_HEAD_STATE_FINGERPRINT nerve_HeadState_FINGERPRINT

/* nerve::Situation */
typedef struct nerve_Situation {
  uint64_t stamp_ns;
  float danger;
  float target_size;
  float target_bearing_rad;
  uint8_t danger_level;
  uint8_t target;
  uint8_t reports;
  uint8_t reserved;
} nerve_Situation;
NERVE_STATIC_ASSERT(sizeof(nerve_Situation) == 24, "nerve::Situation is 24 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_Situation) == 8, "nerve::Situation is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, stamp_ns) == 0, "nerve::Situation.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, danger) == 8, "nerve::Situation.danger is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, target_size) == 12, "nerve::Situation.target_size is at byte 12");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, target_bearing_rad) == 16, "nerve::Situation.target_bearing_rad is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, danger_level) == 20, "nerve::Situation.danger_level is at byte 20");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, target) == 21, "nerve::Situation.target is at byte 21");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, reports) == 22, "nerve::Situation.reports is at byte 22");
NERVE_STATIC_ASSERT(offsetof(nerve_Situation, reserved) == 23, "nerve::Situation.reserved is at byte 23");

#define nerve_Situation_TYPE_NAME "nerve::Situation"
#define nerve_Situation_FINGERPRINT UINT64_C(0xe79d6834b28f9e2f)
#define NERVE_SITUATION_FINGERPRINT nerve_Situation_FINGERPRINT

/* nerve::Mode */
typedef struct nerve_Mode {
  nerve_FixedName name;
  uint32_t index;
  uint64_t since_ns;
  uint64_t changes;
  uint64_t stamp_ns;
  uint8_t danger_level;
  uint8_t target;
  uint8_t load_level;
  uint8_t reserved[5];
} nerve_Mode;
NERVE_STATIC_ASSERT(sizeof(nerve_Mode) == 72, "nerve::Mode is 72 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_Mode) == 8, "nerve::Mode is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, name) == 0, "nerve::Mode.name is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, index) == 36, "nerve::Mode.index is at byte 36");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, since_ns) == 40, "nerve::Mode.since_ns is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, changes) == 48, "nerve::Mode.changes is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, stamp_ns) == 56, "nerve::Mode.stamp_ns is at byte 56");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, danger_level) == 64, "nerve::Mode.danger_level is at byte 64");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, target) == 65, "nerve::Mode.target is at byte 65");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, load_level) == 66, "nerve::Mode.load_level is at byte 66");
NERVE_STATIC_ASSERT(offsetof(nerve_Mode, reserved) == 67, "nerve::Mode.reserved is at byte 67");

#define nerve_Mode_TYPE_NAME "nerve::Mode"
#define nerve_Mode_FINGERPRINT UINT64_C(0x92c82f904d1ee5e8)
#define NERVE_MODE_FINGERPRINT nerve_Mode_FINGERPRINT

/* nerve::AgentLoad */
typedef struct nerve_AgentLoad {
  nerve_FixedName name;
  float cpu_percent;
  uint64_t rss_bytes;
  uint8_t importance;
  uint8_t action;
  uint8_t reserved[6];
} nerve_AgentLoad;
NERVE_STATIC_ASSERT(sizeof(nerve_AgentLoad) == 56, "nerve::AgentLoad is 56 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_AgentLoad) == 8, "nerve::AgentLoad is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, name) == 0, "nerve::AgentLoad.name is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, cpu_percent) == 36, "nerve::AgentLoad.cpu_percent is at byte 36");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, rss_bytes) == 40, "nerve::AgentLoad.rss_bytes is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, importance) == 48, "nerve::AgentLoad.importance is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, action) == 49, "nerve::AgentLoad.action is at byte 49");
NERVE_STATIC_ASSERT(offsetof(nerve_AgentLoad, reserved) == 50, "nerve::AgentLoad.reserved is at byte 50");

#define nerve_AgentLoad_TYPE_NAME "nerve::AgentLoad"
#define nerve_AgentLoad_FINGERPRINT UINT64_C(0x10ff88a02d147f6c)
#define NERVE_AGENT_LOAD_FINGERPRINT nerve_AgentLoad_FINGERPRINT

/* nerve::ResourceHeader */
typedef struct nerve_ResourceHeader {
  uint64_t stamp_ns;
  float machine_cpu_percent;
  float agents_cpu_percent;
  uint64_t mem_total_bytes;
  uint64_t mem_used_bytes;
  uint64_t agents_rss_bytes;
  uint32_t cpus;
  uint32_t agents;
  uint16_t slowed;
  uint16_t suspended;
  uint8_t level;
} nerve_ResourceHeader;
NERVE_STATIC_ASSERT(sizeof(nerve_ResourceHeader) == 56, "nerve::ResourceHeader is 56 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_ResourceHeader) == 8, "nerve::ResourceHeader is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, stamp_ns) == 0, "nerve::ResourceHeader.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, machine_cpu_percent) == 8, "nerve::ResourceHeader.machine_cpu_percent is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, agents_cpu_percent) == 12, "nerve::ResourceHeader.agents_cpu_percent is at byte 12");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, mem_total_bytes) == 16, "nerve::ResourceHeader.mem_total_bytes is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, mem_used_bytes) == 24, "nerve::ResourceHeader.mem_used_bytes is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, agents_rss_bytes) == 32, "nerve::ResourceHeader.agents_rss_bytes is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, cpus) == 40, "nerve::ResourceHeader.cpus is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, agents) == 44, "nerve::ResourceHeader.agents is at byte 44");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, slowed) == 48, "nerve::ResourceHeader.slowed is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, suspended) == 50, "nerve::ResourceHeader.suspended is at byte 50");
NERVE_STATIC_ASSERT(offsetof(nerve_ResourceHeader, level) == 52, "nerve::ResourceHeader.level is at byte 52");

#define nerve_ResourceHeader_TYPE_NAME "nerve::ResourceHeader"
#define nerve_ResourceHeader_FINGERPRINT UINT64_C(0xb36e474be964c7ff)
#define NERVE_RESOURCE_HEADER_FINGERPRINT nerve_ResourceHeader_FINGERPRINT

/* nerve::PoseEstimate */
typedef struct nerve_PoseEstimate {
  double x;
  double y;
  double theta;
  double v;
  double omega;
  uint64_t stamp_ns;
  uint32_t corrections;
  uint8_t source;
  uint8_t last_checkpoint;
  uint8_t reserved[2];
} nerve_PoseEstimate;
NERVE_STATIC_ASSERT(sizeof(nerve_PoseEstimate) == 56, "nerve::PoseEstimate is 56 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_PoseEstimate) == 8, "nerve::PoseEstimate is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, x) == 0, "nerve::PoseEstimate.x is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, y) == 8, "nerve::PoseEstimate.y is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, theta) == 16, "nerve::PoseEstimate.theta is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, v) == 24, "nerve::PoseEstimate.v is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, omega) == 32, "nerve::PoseEstimate.omega is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, stamp_ns) == 40, "nerve::PoseEstimate.stamp_ns is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, corrections) == 48, "nerve::PoseEstimate.corrections is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, source) == 52, "nerve::PoseEstimate.source is at byte 52");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, last_checkpoint) == 53, "nerve::PoseEstimate.last_checkpoint is at byte 53");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseEstimate, reserved) == 54, "nerve::PoseEstimate.reserved is at byte 54");

#define nerve_PoseEstimate_TYPE_NAME "nerve::PoseEstimate"
#define nerve_PoseEstimate_FINGERPRINT UINT64_C(0x106328e2280d4d86)
#define NERVE_POSE_ESTIMATE_FINGERPRINT nerve_PoseEstimate_FINGERPRINT

/* nerve::PoseCorrection */
typedef struct nerve_PoseCorrection {
  double x;
  double y;
  double theta;
  double checkpoint_x;
  double checkpoint_y;
  uint64_t stamp_ns;
  float range_m;
  float bearing_rad;
  uint8_t fields;
  uint8_t source;
  uint8_t checkpoint_id;
  uint8_t reserved[5];
} nerve_PoseCorrection;
NERVE_STATIC_ASSERT(sizeof(nerve_PoseCorrection) == 64, "nerve::PoseCorrection is 64 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_PoseCorrection) == 8, "nerve::PoseCorrection is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, x) == 0, "nerve::PoseCorrection.x is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, y) == 8, "nerve::PoseCorrection.y is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, theta) == 16, "nerve::PoseCorrection.theta is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, checkpoint_x) == 24, "nerve::PoseCorrection.checkpoint_x is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, checkpoint_y) == 32, "nerve::PoseCorrection.checkpoint_y is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, stamp_ns) == 40, "nerve::PoseCorrection.stamp_ns is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, range_m) == 48, "nerve::PoseCorrection.range_m is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, bearing_rad) == 52, "nerve::PoseCorrection.bearing_rad is at byte 52");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, fields) == 56, "nerve::PoseCorrection.fields is at byte 56");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, source) == 57, "nerve::PoseCorrection.source is at byte 57");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, checkpoint_id) == 58, "nerve::PoseCorrection.checkpoint_id is at byte 58");
NERVE_STATIC_ASSERT(offsetof(nerve_PoseCorrection, reserved) == 59, "nerve::PoseCorrection.reserved is at byte 59");

#define nerve_PoseCorrection_TYPE_NAME "nerve::PoseCorrection"
#define nerve_PoseCorrection_FINGERPRINT UINT64_C(0xe89a5ccbb6b0ba67)
#define NERVE_POSE_CORRECTION_FINGERPRINT nerve_PoseCorrection_FINGERPRINT

/* nerve::CheckpointSighting */
typedef struct nerve_CheckpointSighting {
  uint64_t stamp_ns;
  double x;
  double y;
  float range_m;
  float bearing_rad;
  float facing_rad;
  uint8_t checkpoint_id;
  uint8_t transmitters;
  uint8_t from_ir;
  uint8_t from_camera;
  uint8_t is_target;
  uint8_t reserved[7];
} nerve_CheckpointSighting;
NERVE_STATIC_ASSERT(sizeof(nerve_CheckpointSighting) == 48, "nerve::CheckpointSighting is 48 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_CheckpointSighting) == 8, "nerve::CheckpointSighting is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, stamp_ns) == 0, "nerve::CheckpointSighting.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, x) == 8, "nerve::CheckpointSighting.x is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, y) == 16, "nerve::CheckpointSighting.y is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, range_m) == 24, "nerve::CheckpointSighting.range_m is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, bearing_rad) == 28, "nerve::CheckpointSighting.bearing_rad is at byte 28");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, facing_rad) == 32, "nerve::CheckpointSighting.facing_rad is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, checkpoint_id) == 36, "nerve::CheckpointSighting.checkpoint_id is at byte 36");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, transmitters) == 37, "nerve::CheckpointSighting.transmitters is at byte 37");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, from_ir) == 38, "nerve::CheckpointSighting.from_ir is at byte 38");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, from_camera) == 39, "nerve::CheckpointSighting.from_camera is at byte 39");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, is_target) == 40, "nerve::CheckpointSighting.is_target is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_CheckpointSighting, reserved) == 41, "nerve::CheckpointSighting.reserved is at byte 41");

#define nerve_CheckpointSighting_TYPE_NAME "nerve::CheckpointSighting"
#define nerve_CheckpointSighting_FINGERPRINT UINT64_C(0xe1c49ed283b91601)
#define NERVE_CHECKPOINT_SIGHTING_FINGERPRINT nerve_CheckpointSighting_FINGERPRINT

/* nerve::ViaPathHeader */
typedef struct nerve_ViaPathHeader {
  uint64_t stamp_ns;
  uint32_t path_id;
} nerve_ViaPathHeader;
NERVE_STATIC_ASSERT(sizeof(nerve_ViaPathHeader) == 16, "nerve::ViaPathHeader is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_ViaPathHeader) == 8, "nerve::ViaPathHeader is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPathHeader, stamp_ns) == 0, "nerve::ViaPathHeader.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPathHeader, path_id) == 8, "nerve::ViaPathHeader.path_id is at byte 8");

#define nerve_ViaPathHeader_TYPE_NAME "nerve::ViaPathHeader"
#define nerve_ViaPathHeader_FINGERPRINT UINT64_C(0x8f8c36ef336e1b47)
#define NERVE_VIA_PATH_HEADER_FINGERPRINT nerve_ViaPathHeader_FINGERPRINT

/* nerve::ViaPoint */
typedef struct nerve_ViaPoint {
  double point[2];
  double landmark[2];
  uint8_t kind;
  uint8_t checkpoint_id;
} nerve_ViaPoint;
NERVE_STATIC_ASSERT(sizeof(nerve_ViaPoint) == 40, "nerve::ViaPoint is 40 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_ViaPoint) == 8, "nerve::ViaPoint is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPoint, point) == 0, "nerve::ViaPoint.point is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPoint, landmark) == 16, "nerve::ViaPoint.landmark is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPoint, kind) == 32, "nerve::ViaPoint.kind is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_ViaPoint, checkpoint_id) == 33, "nerve::ViaPoint.checkpoint_id is at byte 33");

#define nerve_ViaPoint_TYPE_NAME "nerve::ViaPoint"
#define nerve_ViaPoint_FINGERPRINT UINT64_C(0xd60e2a3f0416ab6e)
#define NERVE_VIA_POINT_FINGERPRINT nerve_ViaPoint_FINGERPRINT

/* nerve::MissionCommand */
typedef struct nerve_MissionCommand {
  uint64_t stamp_ns;
  double x;
  double y;
  uint32_t code;
  uint32_t path_id;
  uint32_t index;
  uint32_t reserved;
} nerve_MissionCommand;
NERVE_STATIC_ASSERT(sizeof(nerve_MissionCommand) == 40, "nerve::MissionCommand is 40 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_MissionCommand) == 8, "nerve::MissionCommand is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, stamp_ns) == 0, "nerve::MissionCommand.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, x) == 8, "nerve::MissionCommand.x is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, y) == 16, "nerve::MissionCommand.y is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, code) == 24, "nerve::MissionCommand.code is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, path_id) == 28, "nerve::MissionCommand.path_id is at byte 28");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, index) == 32, "nerve::MissionCommand.index is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_MissionCommand, reserved) == 36, "nerve::MissionCommand.reserved is at byte 36");

#define nerve_MissionCommand_TYPE_NAME "nerve::MissionCommand"
#define nerve_MissionCommand_FINGERPRINT UINT64_C(0xd6de8056c18d1cd0)
#define NERVE_MISSION_COMMAND_FINGERPRINT nerve_MissionCommand_FINGERPRINT

/* nerve::GraspRequest */
typedef struct nerve_GraspRequest {
  uint64_t stamp_ns;
  double x;
  double y;
  uint32_t request_id;
  uint8_t action;
  uint8_t has_point;
  uint8_t reserved[2];
} nerve_GraspRequest;
NERVE_STATIC_ASSERT(sizeof(nerve_GraspRequest) == 32, "nerve::GraspRequest is 32 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_GraspRequest) == 8, "nerve::GraspRequest is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, stamp_ns) == 0, "nerve::GraspRequest.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, x) == 8, "nerve::GraspRequest.x is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, y) == 16, "nerve::GraspRequest.y is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, request_id) == 24, "nerve::GraspRequest.request_id is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, action) == 28, "nerve::GraspRequest.action is at byte 28");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, has_point) == 29, "nerve::GraspRequest.has_point is at byte 29");
NERVE_STATIC_ASSERT(offsetof(nerve_GraspRequest, reserved) == 30, "nerve::GraspRequest.reserved is at byte 30");

#define nerve_GraspRequest_TYPE_NAME "nerve::GraspRequest"
#define nerve_GraspRequest_FINGERPRINT UINT64_C(0x863b45698e059378)
#define NERVE_GRASP_REQUEST_FINGERPRINT nerve_GraspRequest_FINGERPRINT

/* nerve::ArmGraspState */
typedef struct nerve_ArmGraspState {
  uint64_t stamp_ns;
  float joints_rad[3];
  float nearest_m;
  uint32_t request_id;
  uint8_t phase;
  uint8_t held_id;
  uint8_t reason;
  uint8_t connected;
} nerve_ArmGraspState;
NERVE_STATIC_ASSERT(sizeof(nerve_ArmGraspState) == 32, "nerve::ArmGraspState is 32 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_ArmGraspState) == 8, "nerve::ArmGraspState is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, stamp_ns) == 0, "nerve::ArmGraspState.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, joints_rad) == 8, "nerve::ArmGraspState.joints_rad is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, nearest_m) == 20, "nerve::ArmGraspState.nearest_m is at byte 20");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, request_id) == 24, "nerve::ArmGraspState.request_id is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, phase) == 28, "nerve::ArmGraspState.phase is at byte 28");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, held_id) == 29, "nerve::ArmGraspState.held_id is at byte 29");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, reason) == 30, "nerve::ArmGraspState.reason is at byte 30");
NERVE_STATIC_ASSERT(offsetof(nerve_ArmGraspState, connected) == 31, "nerve::ArmGraspState.connected is at byte 31");

#define nerve_ArmGraspState_TYPE_NAME "nerve::ArmGraspState"
#define nerve_ArmGraspState_FINGERPRINT UINT64_C(0x53eab0fb2bc901fb)
#define NERVE_ARM_GRASP_STATE_FINGERPRINT nerve_ArmGraspState_FINGERPRINT

/* nerve::MapCell */
typedef struct nerve_MapCell {
  uint64_t last_seen_ns;
  int32_t ix;
  int32_t iy;
  float x;
  float y;
  uint32_t visits;
  uint8_t flags;
} nerve_MapCell;
NERVE_STATIC_ASSERT(sizeof(nerve_MapCell) == 32, "nerve::MapCell is 32 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_MapCell) == 8, "nerve::MapCell is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, last_seen_ns) == 0, "nerve::MapCell.last_seen_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, ix) == 8, "nerve::MapCell.ix is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, iy) == 12, "nerve::MapCell.iy is at byte 12");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, x) == 16, "nerve::MapCell.x is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, y) == 20, "nerve::MapCell.y is at byte 20");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, visits) == 24, "nerve::MapCell.visits is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_MapCell, flags) == 28, "nerve::MapCell.flags is at byte 28");

#define nerve_MapCell_TYPE_NAME "nerve::MapCell"
#define nerve_MapCell_FINGERPRINT UINT64_C(0x0a696c4b8972882d)
#define NERVE_MAP_CELL_FINGERPRINT nerve_MapCell_FINGERPRINT

/* nerve::MapHeader */
typedef struct nerve_MapHeader {
  uint64_t stamp_ns;
  double cell_m;
  double origin_x;
  double origin_y;
  int32_t min_ix;
  int32_t min_iy;
  int32_t max_ix;
  int32_t max_iy;
  uint32_t count;
  uint32_t revision;
  uint32_t max_cells;
  uint8_t full;
} nerve_MapHeader;
NERVE_STATIC_ASSERT(sizeof(nerve_MapHeader) == 64, "nerve::MapHeader is 64 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_MapHeader) == 8, "nerve::MapHeader is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, stamp_ns) == 0, "nerve::MapHeader.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, cell_m) == 8, "nerve::MapHeader.cell_m is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, origin_x) == 16, "nerve::MapHeader.origin_x is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, origin_y) == 24, "nerve::MapHeader.origin_y is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, min_ix) == 32, "nerve::MapHeader.min_ix is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, min_iy) == 36, "nerve::MapHeader.min_iy is at byte 36");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, max_ix) == 40, "nerve::MapHeader.max_ix is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, max_iy) == 44, "nerve::MapHeader.max_iy is at byte 44");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, count) == 48, "nerve::MapHeader.count is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, revision) == 52, "nerve::MapHeader.revision is at byte 52");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, max_cells) == 56, "nerve::MapHeader.max_cells is at byte 56");
NERVE_STATIC_ASSERT(offsetof(nerve_MapHeader, full) == 60, "nerve::MapHeader.full is at byte 60");

#define nerve_MapHeader_TYPE_NAME "nerve::MapHeader"
#define nerve_MapHeader_FINGERPRINT UINT64_C(0x8db3cac041cc2647)
#define NERVE_MAP_HEADER_FINGERPRINT nerve_MapHeader_FINGERPRINT

/* nerve::PlanRequest */
typedef struct nerve_PlanRequest {
  double x;
  double y;
  uint64_t stamp_ns;
} nerve_PlanRequest;
NERVE_STATIC_ASSERT(sizeof(nerve_PlanRequest) == 24, "nerve::PlanRequest is 24 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_PlanRequest) == 8, "nerve::PlanRequest is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_PlanRequest, x) == 0, "nerve::PlanRequest.x is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_PlanRequest, y) == 8, "nerve::PlanRequest.y is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_PlanRequest, stamp_ns) == 16, "nerve::PlanRequest.stamp_ns is at byte 16");

#define nerve_PlanRequest_TYPE_NAME "nerve::PlanRequest"
#define nerve_PlanRequest_FINGERPRINT UINT64_C(0xaabd2787a438eed7)
#define NERVE_PLAN_REQUEST_FINGERPRINT nerve_PlanRequest_FINGERPRINT

/* nerve::PathPoint */
typedef struct nerve_PathPoint {
  double x;
  double y;
} nerve_PathPoint;
NERVE_STATIC_ASSERT(sizeof(nerve_PathPoint) == 16, "nerve::PathPoint is 16 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_PathPoint) == 8, "nerve::PathPoint is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_PathPoint, x) == 0, "nerve::PathPoint.x is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_PathPoint, y) == 8, "nerve::PathPoint.y is at byte 8");

#define nerve_PathPoint_TYPE_NAME "nerve::PathPoint"
#define nerve_PathPoint_FINGERPRINT UINT64_C(0xe08a887050b19791)
#define NERVE_PATH_POINT_FINGERPRINT nerve_PathPoint_FINGERPRINT

/* nerve::PathHeader */
typedef struct nerve_PathHeader {
  uint64_t stamp_ns;
  double goal_x;
  double goal_y;
  double start_x;
  double start_y;
  double length_m;
  uint32_t cells;
  uint8_t status;
} nerve_PathHeader;
NERVE_STATIC_ASSERT(sizeof(nerve_PathHeader) == 56, "nerve::PathHeader is 56 bytes");
NERVE_STATIC_ASSERT(NERVE_ALIGNOF(nerve_PathHeader) == 8, "nerve::PathHeader is aligned to 8 bytes");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, stamp_ns) == 0, "nerve::PathHeader.stamp_ns is at byte 0");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, goal_x) == 8, "nerve::PathHeader.goal_x is at byte 8");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, goal_y) == 16, "nerve::PathHeader.goal_y is at byte 16");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, start_x) == 24, "nerve::PathHeader.start_x is at byte 24");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, start_y) == 32, "nerve::PathHeader.start_y is at byte 32");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, length_m) == 40, "nerve::PathHeader.length_m is at byte 40");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, cells) == 48, "nerve::PathHeader.cells is at byte 48");
NERVE_STATIC_ASSERT(offsetof(nerve_PathHeader, status) == 52, "nerve::PathHeader.status is at byte 52");

#define nerve_PathHeader_TYPE_NAME "nerve::PathHeader"
#define nerve_PathHeader_FINGERPRINT UINT64_C(0x19ed07a8512ba1ab)
#define NERVE_PATH_HEADER_FINGERPRINT nerve_PathHeader_FINGERPRINT

/* X(T) for every built-in payload type T. */
#define NERVE_BUILTIN_PAYLOADS(X) \
  X(nerve_Tick) \
  X(nerve_RouterEpoch) \
  X(nerve_Scalar) \
  X(nerve_RingNotice) \
  X(nerve_SonarScan) \
  X(nerve_VelocityCommand) \
  X(nerve_LinguisticCommand) \
  X(nerve_SafetyStop) \
  X(nerve_Odometry) \
  X(nerve_GroundTruth) \
  X(nerve_IrSighting) \
  X(nerve_HeadCommand) \
  X(nerve_HeadState) \
  X(nerve_Situation) \
  X(nerve_Mode) \
  X(nerve_AgentLoad) \
  X(nerve_ResourceHeader) \
  X(nerve_PoseEstimate) \
  X(nerve_PoseCorrection) \
  X(nerve_CheckpointSighting) \
  X(nerve_ViaPathHeader) \
  X(nerve_ViaPoint) \
  X(nerve_MissionCommand) \
  X(nerve_GraspRequest) \
  X(nerve_ArmGraspState) \
  X(nerve_MapCell) \
  X(nerve_MapHeader) \
  X(nerve_PlanRequest) \
  X(nerve_PathPoint) \
  X(nerve_PathHeader)

#endif /* NERVE_TYPES_H */
