/* Fuzz target: the keyframe database behind loop closure (topoloc_loop_detector_*). The input
 * is a program of operations (add a keyframe with descriptor, pose, keypoints, binary
 * descriptors and scene points; erase; query; read confirmed hints) run on a fresh detector
 * with intrinsics, so that hints with relative poses are computed. */
#include "common.h"

#define DIM 16
#define MAX_KEYPOINTS 96

static void read_pose(fuzz_reader *r, double pose[16])
{
    /* A rotation about z by a fuzzed angle and a fuzzed translation, sometimes raw floats
     * (not a rigid transform, non-finite). */
    uint8_t kind = fuzz_u8(r);
    double a = fuzz_f32(r), tx = fuzz_f32(r), ty = fuzz_f32(r), tz = fuzz_f32(r);
    double c = __builtin_cos(a), s = __builtin_sin(a);
    double rigid[16] = {c, -s, 0, tx, s, c, 0, ty, 0, 0, 1, tz, 0, 0, 0, 1};
    for (int i = 0; i < 16; i++)
        pose[i] = (kind & 7) == 0 ? fuzz_f32(r) : rigid[i];
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_reader r = {data, size};
    topoloc_loop_options options;
    topoloc_loop_options_default(&options);
    options.fx = options.fy = 160;
    options.cx = 160;
    options.cy = 120;
    options.candidates = 1 + fuzz_u8(&r) % 8;
    options.min_inliers = fuzz_u8(&r) % 40;
    options.consistent_keyframes = fuzz_u8(&r) % 4;
    options.exclude_recent_ids = fuzz_u8(&r) % 8;
    topoloc_loop_detector *det = NULL;
    topoloc_status s = CHECK(topoloc_loop_detector_new("fuzz", "fuzz", DIM, &options, &det));
    EXPECT_NULL_ON_ERROR(s, det);
    if (s != TOPOLOC_OK)
        return 0;

    uint64_t id = 0;
    double t = 0;
    float descriptor[DIM];
    double world_T_body[16], body_T_camera[16];
    static float keypoints[2 * MAX_KEYPOINTS], points[3 * MAX_KEYPOINTS];
    static uint8_t binary[32 * MAX_KEYPOINTS];
    for (int op = 0; op < 24 && r.n > 0; op++) {
        uint8_t code = fuzz_u8(&r);
        switch (code % 5) {
        case 0:
        case 1: {
            topoloc_loop_keyframe kf;
            topoloc_loop_keyframe_default(&kf);
            id += (code & 0x80) ? 0 : 1 + (fuzz_u8(&r) & 3); /* sometimes a repeated id */
            t += (code & 0x40) ? -1.0 : 0.5;                 /* sometimes time going back */
            kf.id = id;
            kf.timestamp = t;
            for (int i = 0; i < DIM; i++)
                descriptor[i] = fuzz_f32(&r);
            kf.descriptor = descriptor;
            kf.descriptor_len = (code & 0x20) ? DIM - 1 : DIM;
            if (code & 0x10) {
                read_pose(&r, world_T_body);
                kf.world_T_body = world_T_body;
            }
            if (code & 0x08) {
                read_pose(&r, body_T_camera);
                kf.body_T_camera = body_T_camera;
            }
            size_t n = fuzz_u8(&r) % (MAX_KEYPOINTS + 1);
            for (size_t i = 0; i < n; i++) {
                keypoints[2 * i] = 160 + 40 * fuzz_f32(&r);
                keypoints[2 * i + 1] = 120 + 30 * fuzz_f32(&r);
                for (int b = 0; b < 32; b++)
                    binary[32 * i + b] = (uint8_t)(fuzz_u8(&r) * (b + 1));
                for (int k = 0; k < 3; k++)
                    points[3 * i + k] = k == 2 ? 2 + fuzz_f32(&r) : fuzz_f32(&r);
            }
            kf.keypoint_count = (code & 0x04) ? 5001 : n; /* sometimes above the bound */
            kf.keypoints = keypoints;
            kf.keypoint_descriptors = binary;
            kf.camera_points = (code & 0x02) ? points : NULL;
            topoloc_loop_hint hint;
            topoloc_loop_hint_default(&hint);
            CHECK(topoloc_loop_detector_add(det, &kf, &hint));
            break;
        }
        case 2:
            CHECK(topoloc_loop_detector_erase(det, id - (fuzz_u8(&r) % 4)));
            break;
        case 3: {
            topoloc_loop_candidate cands[8];
            size_t count = 0;
            for (int i = 0; i < DIM; i++)
                descriptor[i] = fuzz_f32(&r);
            CHECK(
                topoloc_loop_detector_query(det, descriptor, DIM, cands, fuzz_u8(&r) % 9, &count));
            break;
        }
        default: {
            size_t count = 0, len = 0;
            CHECK(topoloc_loop_detector_confirmed_count(det, &count));
            CHECK(topoloc_loop_detector_len(det, &len));
            for (size_t i = 0; i <= count && i < 4; i++) {
                topoloc_loop_hint hint;
                topoloc_loop_hint_default(&hint);
                CHECK(topoloc_loop_detector_confirmed(det, i, &hint));
            }
        }
        }
    }
    topoloc_loop_detector_free(det);
    return 0;
}
