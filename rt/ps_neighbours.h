/*
 * ps_neighbours: the neighbours' shoulders as the camera saw them, the
 * neutral type that crosses from the perception thread (rt/ps_perception)
 * through the mailbox (rt/ps_mailbox) into the loop's measurements
 * (policy/ps_state.h, ps_meas_t.neighbours), where the policy's observation
 * builder reads it. Base layer: plain data, no functions, so that policy/
 * may include it.
 *
 * Robot frame: the pelvis (IMU) frame of policy/ps_state.h: origin at the
 * IMU site, x forward, y left, z up. A shoulder's position is the centre of
 * the AprilTag worn on it (docs/perception.md).
 *
 * Tag ids name the shoulders: neighbour = id / 2, side = id % 2 (0 left,
 * 1 right), so one person wears ids 2k and 2k + 1.
 *
 * Threads: any (a value type). Allocation: none.
 */
#ifndef PS_NEIGHBOURS_H
#define PS_NEIGHBOURS_H

#include <stdbool.h>
#include <stdint.h>

/** Shoulders one list holds: 16 people, both shoulders seen. */
#define PS_MAX_SHOULDERS 32u

typedef enum {
    PS_SHOULDER_LEFT = 0,
    PS_SHOULDER_RIGHT = 1,
} ps_shoulder_side_t;

typedef struct {
    float pos_robot_m[3]; /**< tag centre in the robot (pelvis) frame */
    float confidence;     /**< 0..1: the detector's decision margin and the pose's
                               reprojection fit, combined (docs/perception.md) */
    uint16_t neighbour_id; /**< tag id / 2 */
    uint8_t side;          /**< ps_shoulder_side_t: tag id % 2 */
    uint8_t pad;
} ps_shoulder_t;

typedef struct {
    uint32_t n_shoulders;
    ps_shoulder_t shoulders[PS_MAX_SHOULDERS];
    int64_t t_exposure_ns; /**< when the frame was exposed, on the loop's clock
                                (simulated time on board sim); 0: never */
    uint64_t frame_seq;    /**< the camera's frame number */
    /* Set by the loop on its copy (ps_meas_t.neighbours), each tick: */
    bool is_valid;  /**< a list no older than the configured age; when false the
                         list is empty: no neighbour information */
    int64_t age_ns; /**< tick deadline minus t_exposure_ns (the last list taken) */
} ps_neighbours_t;

#endif /* PS_NEIGHBOURS_H */
