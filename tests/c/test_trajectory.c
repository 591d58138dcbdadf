/*
 * Section "Trajectory metrics" of topoloc.h (ABI 1.11): a scaled, moved copy of a circle aligns
 * back exactly with TOPOLOC_ALIGN_SIM3 and not with TOPOLOC_ALIGN_SE3; bad input is refused
 * with the report unchanged; trajectories in TUM files, their format detected, and malformed or
 * missing files.
 */
#include "harness.h"

#include <math.h>

#define TRAJ_N 40

/* A reference circle and an estimate of it at half the scale, moved 4 m along x. */
struct trajectories {
    double ref_t[TRAJ_N], ref_p[7 * TRAJ_N], est_t[TRAJ_N], est_p[7 * TRAJ_N];
};

static void circle_trajectory(double *stamps, double *poses, double scale, double dx)
{
    for (int i = 0; i < TRAJ_N; i++) {
        double a = 6.283185307179586 * i / TRAJ_N;
        double *p = poses + 7 * i;
        stamps[i] = 0.1 * i;
        p[0] = scale * 3.0 * cos(a) + dx;
        p[1] = scale * 2.0 * sin(a);
        p[2] = scale * 0.2 * i / TRAJ_N;
        p[3] = 0.0; /* qx qy qz qw: a yaw of a */
        p[4] = 0.0;
        p[5] = sin(a / 2);
        p[6] = cos(a / 2);
    }
}

/* The reference against the first `est_n` poses of the estimate. */
static topoloc_status evaluate(const struct trajectories *t, size_t est_n,
                               const topoloc_trajectory_options *options,
                               topoloc_trajectory_report *report)
{
    return topoloc_trajectory_evaluate(t->ref_t, t->ref_p, TRAJ_N, t->est_t, t->est_p, est_n,
                                       options, report);
}

/* Leaves `options` at SE3 and `report` with the SE3 run's figures. */
static void a_scaled_moved_circle_aligns_back_exactly_with_sim3_and_not_with_se3(
    const struct trajectories *t, topoloc_trajectory_options *options,
    topoloc_trajectory_report *report)
{
    SECTION();
    CHECK(topoloc_abi_version_minor() >= 11);
    CHECK_STATUS(topoloc_trajectory_options_default(options), TOPOLOC_OK);
    CHECK(options->alignment == TOPOLOC_ALIGN_SIM3 && options->max_diff_s == 0.01 &&
          options->offset_s == 0.0 && options->rpe_delta == 1);
    CHECK_STATUS(topoloc_trajectory_report_default(report), TOPOLOC_OK);
    CHECK_STATUS(evaluate(t, TRAJ_N, options, report), TOPOLOC_OK);
    CHECK(report->pairs == TRAJ_N && report->ate_m.rmse < 1e-9 && report->are_deg.max < 1e-6);
    CHECK(fabs(report->scale - 2.0) < 1e-9 && fabs(report->length_ratio - 1.0) < 1e-9);
    CHECK(fabs(report->alignment[15] - 1.0) < 1e-12);
    options->alignment = TOPOLOC_ALIGN_SE3;
    CHECK_STATUS(evaluate(t, TRAJ_N, options, report), TOPOLOC_OK);
    CHECK(report->scale == 1.0 && report->ate_m.rmse > 0.5);
}

/* An unknown alignment, a NaN, a timestamp going back, too few pairs, NULLs and a short report:
 * a status each, and the report as it was. */
static void bad_trajectories_and_options_are_refused_with_the_report_unchanged(
    struct trajectories *t, topoloc_trajectory_options *options, topoloc_trajectory_report *report)
{
    SECTION();
    options->alignment = 7;
    CHECK_STATUS(evaluate(t, TRAJ_N, options, report), TOPOLOC_ERR_INVALID_OPTION);
    options->alignment = TOPOLOC_ALIGN_SIM3;
    t->est_p[7 * 5 + 1] = make_nan();
    CHECK_STATUS(evaluate(t, TRAJ_N, options, report), TOPOLOC_ERR_NON_FINITE);
    t->est_p[7 * 5 + 1] = 0.0;
    t->est_t[3] = -1.0; /* earlier than the one before */
    CHECK_ERROR(evaluate(t, TRAJ_N, options, report), TOPOLOC_ERR_INVALID_ARGUMENT);
    t->est_t[3] = 0.3;
    CHECK_STATUS(evaluate(t, 2, options, report),
                 TOPOLOC_ERR_INVALID_ARGUMENT); /* too few pairs to align */
    CHECK_NULL(topoloc_trajectory_evaluate(t->ref_t, NULL, TRAJ_N, t->est_t, t->est_p, TRAJ_N,
                                           options, report),
               "reference_poses");
    CHECK_NULL(evaluate(t, TRAJ_N, options, NULL), "report");
    report->struct_size = 3;
    CHECK_STATUS(evaluate(t, TRAJ_N, NULL, report), TOPOLOC_ERR_STRUCT_SIZE);
    report->struct_size = sizeof *report;
    CHECK(report->scale == 1.0 && report->pairs == TRAJ_N); /* the SE3 run's, untouched */
}

static void
tum_files_are_detected_and_malformed_or_missing_files_refused(const struct trajectories *t,
                                                              topoloc_trajectory_report *report)
{
    char ref_path[4200], est_path[4200];
    FILE *f;

    SECTION();
    tmp_path(ref_path, sizeof ref_path, "ref.tum");
    tmp_path(est_path, sizeof est_path, "est.tum");
    f = fopen(ref_path, "w");
    CHECK(f != NULL);
    if (f == NULL)
        return;
    fprintf(f, "# timestamp tx ty tz qx qy qz qw\n");
    for (int i = 0; i < TRAJ_N; i++) {
        const double *p = t->ref_p + 7 * i;
        fprintf(f, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", t->ref_t[i], p[0], p[1],
                p[2], p[3], p[4], p[5], p[6]);
    }
    fclose(f);
    f = fopen(est_path, "w");
    CHECK(f != NULL);
    if (f == NULL)
        return;
    fprintf(f, "0.0 1 2 3 0 0 0 1\nnot a pose\n");
    fclose(f);
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, ref_path, TOPOLOC_TRAJECTORY_DETECT,
                                                   NULL, report),
                 TOPOLOC_OK);
    CHECK(report->pairs == TRAJ_N && report->ate_m.rmse < 1e-9);
    CHECK_ERROR(
        topoloc_trajectory_evaluate_files(ref_path, est_path, TOPOLOC_TRAJECTORY_TUM, NULL, report),
        TOPOLOC_ERR_INVALID_ARGUMENT); /* line 2 is malformed */
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, ref_path, 9, NULL, report),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(remove(est_path) == 0);
    CHECK_STATUS(
        topoloc_trajectory_evaluate_files(ref_path, est_path, TOPOLOC_TRAJECTORY_TUM, NULL, report),
        TOPOLOC_ERR_IO);
    CHECK(remove(ref_path) == 0);
}

void run_trajectory_tests(void)
{
    static struct trajectories t;
    topoloc_trajectory_options options;
    topoloc_trajectory_report report;

    circle_trajectory(t.ref_t, t.ref_p, 1.0, 0.0);
    circle_trajectory(t.est_t, t.est_p, 0.5, 4.0);
    a_scaled_moved_circle_aligns_back_exactly_with_sim3_and_not_with_se3(&t, &options, &report);
    bad_trajectories_and_options_are_refused_with_the_report_unchanged(&t, &options, &report);
    tum_files_are_detected_and_malformed_or_missing_files_refused(&t, &report);
}
