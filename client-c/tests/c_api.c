/*
 * Checks of libdear_client's C API from C, run by tests/c_api.rs (which builds this file
 * against the crate's static library and starts deard where a mode needs one):
 *
 *     c_api arguments BAD_SERVICE    NULL arguments, a bad service name (no daemon needed)
 *     c_api timeout SERVICE          no publisher: DEAR_TIMEOUT, naming the service
 *     c_api frames SERVICE           a running deard: planes, header, the held-frames limit
 *     c_api points SERVICE           a running deard: the point cloud of a frame (format 3's
 *                                    intrinsics), checked point by point against the header
 *     c_api distorted SERVICE K1 K2 P1 P2 K3
 *                                    a deard replaying a capture with that distortion: the
 *                                    header carries it, every point reprojects onto its pixel
 *
 * Prints "ok <check>" per check; on the first failed check prints "FAIL ..." and exits 1.
 */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dear_client.h"

static int checks = 0;

#define CHECK(cond, ...)                                                              \
    do {                                                                              \
        if (!(cond)) {                                                                \
            fprintf(stdout, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond);           \
            fprintf(stdout, __VA_ARGS__);                                             \
            fprintf(stdout, " (last error: %s)\n", dear_last_error());                \
            exit(1);                                                                  \
        }                                                                             \
        checks++;                                                                     \
    } while (0)

#define EXPECT_STATUS(call, expected)                                                 \
    do {                                                                              \
        dear_status got_ = (call);                                                    \
        CHECK(got_ == (expected), "%s returned %s, expected %s", #call,               \
              dear_status_name(got_), dear_status_name(expected));                    \
    } while (0)

static void ok(const char *what) {
    printf("ok %s\n", what);
    fflush(stdout);
}

static int mentions(const char *needle) { return strstr(dear_last_error(), needle) != NULL; }

static void arguments(const char *bad_service) {
    CHECK(dear_last_error() != NULL && dear_last_error()[0] == '\0', "no failure yet: empty");

    dear_client *client = (dear_client *)0x1; /* must be overwritten with NULL */
    EXPECT_STATUS(dear_client_connect(NULL, &client), DEAR_INVALID_ARGUMENT);
    CHECK(client == NULL, "*out is NULL after a failure");
    CHECK(mentions("service"), "the message names the NULL argument");
    EXPECT_STATUS(dear_client_connect("dear/cam0/frames", NULL), DEAR_INVALID_ARGUMENT);
    CHECK(mentions("out"), "the message names the NULL argument");

    dear_frame *frame = (dear_frame *)0x1;
    EXPECT_STATUS(dear_client_wait(NULL, 0, &frame), DEAR_INVALID_ARGUMENT);
    CHECK(frame == NULL, "*out is NULL after a failure");
    CHECK(mentions("client"), "the message names the NULL argument");
    EXPECT_STATUS(dear_client_wait(NULL, 0, NULL), DEAR_INVALID_ARGUMENT);

    size_t len = 99;
    CHECK(dear_frame_header(NULL) == NULL, "no header of no frame");
    CHECK(mentions("dear_frame_header") && mentions("frame"), "names function and argument");
    CHECK(dear_frame_depth(NULL, &len) == NULL && len == 0, "no depth of no frame");
    CHECK(dear_frame_rgb(NULL, &len) == NULL && len == 0, "no rgb of no frame");
    CHECK(dear_frame_confidence(NULL, NULL) == NULL, "no confidence of no frame");
    CHECK(mentions("dear_frame_confidence"), "names the function");
    dear_frame_release(NULL); /* no-ops, like free(NULL) */
    dear_client_free(NULL);
    ok("NULL arguments: DEAR_INVALID_ARGUMENT or NULL, with a message");

    client = (dear_client *)0x1;
    EXPECT_STATUS(dear_client_connect(bad_service, &client), DEAR_CONNECT_FAILED);
    CHECK(client == NULL, "*out is NULL after a failure");
    CHECK(mentions(bad_service), "the message names the service");
    printf("bad service: %s\n", dear_last_error());
    ok("a bad service name: DEAR_CONNECT_FAILED naming it");

    CHECK(strcmp(dear_status_name(DEAR_TOO_MANY_FRAMES_HELD), "DEAR_TOO_MANY_FRAMES_HELD") == 0,
          "status names");
    CHECK(sizeof(dear_header) == DEAR_HEADER_SIZE && DEAR_HEADER_SIZE == 256,
          "the header is the protocol's 256 bytes");
    CHECK(strcmp(dear_status_name(DEAR_NO_INTRINSICS), "DEAR_NO_INTRINSICS") == 0, "names");
    CHECK(dear_frame_point_cloud(NULL, NULL, 0, NULL, 0) == DEAR_INVALID_ARGUMENT,
          "no point cloud of no frame");
    CHECK(mentions("dear_frame_point_cloud") && mentions("frame"), "names function, argument");
    ok("status names, header size");
}

static void timeout(const char *service) {
    dear_client *client = NULL;
    EXPECT_STATUS(dear_client_connect(service, &client), DEAR_OK);
    dear_frame *frame = (dear_frame *)0x1;
    EXPECT_STATUS(dear_client_wait(client, 200, &frame), DEAR_TIMEOUT);
    CHECK(frame == NULL, "no frame on a timeout");
    CHECK(mentions(service) && mentions("200 ms"), "the timeout names service and time");
    EXPECT_STATUS(dear_client_wait(client, 0, &frame), DEAR_TIMEOUT);
    dear_client_free(client);
    ok("no publisher: DEAR_TIMEOUT naming the service");
}

static void check_frame(const dear_frame *frame) {
    const dear_header *h = dear_frame_header(frame);
    CHECK(h != NULL, "a header");
    CHECK(h->magic == DEAR_MAGIC && h->version == DEAR_FORMAT_VERSION, "magic, version");
    size_t pixels = (size_t)h->width * h->height;
    CHECK(h->depth_offset == 0 && h->rgb_offset == 4 * pixels &&
              h->confidence_offset == 7 * pixels && h->payload_size == 8 * pixels,
          "offsets of a %" PRIu32 "x%" PRIu32 " frame", h->width, h->height);
    CHECK(h->run_id != 0, "deard draws a run id");
    CHECK(h->depth_unit_m == DEAR_DEPTH_UNIT_M, "depth in metres");
    CHECK(h->calib_health <= DEAR_CALIB_HEALTH_NEEDS_RECALIBRATION && h->calib_constrained <= 4,
          "calibration health %u, %u directions", h->calib_health, h->calib_constrained);
    size_t n_depth = 0, n_rgb = 0, n_conf = 0;
    const float *depth = dear_frame_depth(frame, &n_depth);
    const uint8_t *rgb = dear_frame_rgb(frame, &n_rgb);
    const uint8_t *conf = dear_frame_confidence(frame, &n_conf);
    CHECK(depth && rgb && conf, "planes");
    CHECK(n_depth == pixels && n_rgb == 3 * pixels && n_conf == pixels,
          "plane lengths %zu %zu %zu for %zu pixels", n_depth, n_rgb, n_conf, pixels);
    /* Zero-copy: the planes lie one after another in the sample, as the header says. */
    CHECK((const uint8_t *)depth + h->rgb_offset == rgb, "rgb follows depth in the sample");
    CHECK((const uint8_t *)depth + h->confidence_offset == conf, "confidence follows rgb");
    CHECK(((uintptr_t)depth % sizeof(float)) == 0, "depth is aligned for float");
    size_t valid = 0, agree = 0;
    for (size_t i = 0; i < pixels; i++) {
        valid += depth[i] > 0.0f;
        agree += (depth[i] == 0.0f) == (conf[i] == 0);
    }
    CHECK(valid > 0, "valid depth");
    CHECK(agree == pixels, "confidence is 0 exactly where depth is 0 (%zu of %zu)", agree, pixels);
}

static void frames(const char *service) {
    dear_client *client = NULL;
    EXPECT_STATUS(dear_client_connect(service, &client), DEAR_OK);
    dear_frame *held[DEAR_MAX_HELD_FRAMES] = {NULL};
    uint64_t last_sequence = 0;
    for (int i = 0; i < DEAR_MAX_HELD_FRAMES; i++) {
        EXPECT_STATUS(dear_client_wait(client, 20000, &held[i]), DEAR_OK);
        check_frame(held[i]);
        uint64_t sequence = dear_frame_header(held[i])->sequence;
        CHECK(i == 0 || sequence > last_sequence, "sequence increases");
        last_sequence = sequence;
    }
    ok("frames: header and planes");

    dear_frame *extra = (dear_frame *)0x1;
    EXPECT_STATUS(dear_client_wait(client, 20000, &extra), DEAR_TOO_MANY_FRAMES_HELD);
    CHECK(extra == NULL, "no frame beyond the limit");
    CHECK(mentions(service) && mentions("dear_frame_release"), "the message says what to do");
    printf("held: %s\n", dear_last_error());
    /* The held frames are intact meanwhile. */
    check_frame(held[0]);
    ok("a third held frame: DEAR_TOO_MANY_FRAMES_HELD");

    dear_frame_release(held[0]);
    EXPECT_STATUS(dear_client_wait(client, 20000, &held[0]), DEAR_OK);
    check_frame(held[0]);
    ok("after a release the next frame comes");

    /* Frames outlive their client until released. */
    dear_client_free(client);
    check_frame(held[1]);
    dear_frame_release(held[0]);
    dear_frame_release(held[1]);
    ok("frames released after their client");
}

static void points(const char *service) {
    dear_client *client = NULL;
    EXPECT_STATUS(dear_client_connect(service, &client), DEAR_OK);
    dear_frame *frame = NULL;
    EXPECT_STATUS(dear_client_wait(client, 20000, &frame), DEAR_OK);
    const dear_header *h = dear_frame_header(frame);
    CHECK(h->rgb_camera_model == DEAR_CAMERA_MODEL_PINHOLE, "a replay's camera is a pinhole");
    printf("intrinsics %u %.6f %.6f %.6f %.6f\n", (unsigned)h->rgb_camera_model,
           (double)h->rgb_fx, (double)h->rgb_fy, (double)h->rgb_cx, (double)h->rgb_cy);
    size_t pixels = (size_t)h->width * h->height;
    float *xyz = malloc(3 * pixels * sizeof(float));
    uint8_t *valid = malloc(pixels);
    CHECK(xyz && valid, "memory");

    /* Wrong lengths and NULLs are refused by name, nothing written. */
    EXPECT_STATUS(dear_frame_point_cloud(frame, xyz, 3 * pixels - 1, valid, pixels),
                  DEAR_INVALID_ARGUMENT);
    CHECK(mentions("xyz_len") && mentions("needs"), "the message names xyz_len");
    EXPECT_STATUS(dear_frame_point_cloud(frame, xyz, 3 * pixels, valid, pixels + 1),
                  DEAR_INVALID_ARGUMENT);
    CHECK(mentions("valid_len"), "the message names valid_len");
    EXPECT_STATUS(dear_frame_point_cloud(frame, NULL, 3 * pixels, valid, pixels),
                  DEAR_INVALID_ARGUMENT);
    CHECK(mentions("xyz"), "the message names xyz");

    memset(valid, 7, pixels);
    EXPECT_STATUS(dear_frame_point_cloud(frame, xyz, 3 * pixels, valid, pixels), DEAR_OK);
    const float *depth = dear_frame_depth(frame, NULL);
    size_t n_valid = 0, n_invalid = 0;
    for (uint32_t v = 0; v < h->height; v++) {
        for (uint32_t u = 0; u < h->width; u++) {
            size_t i = (size_t)v * h->width + u;
            float z = depth[i];
            const float *p = xyz + 3 * i;
            if (z > 0.0f && isfinite(z)) {
                float x = ((float)u - h->rgb_cx) * z / h->rgb_fx;
                float y = ((float)v - h->rgb_cy) * z / h->rgb_fy;
                CHECK(valid[i] == 1, "pixel (%u, %u) with depth %f is valid", u, v, (double)z);
                CHECK(fabsf(p[0] - x) <= 1e-5f * fmaxf(1.0f, fabsf(x)) &&
                          fabsf(p[1] - y) <= 1e-5f * fmaxf(1.0f, fabsf(y)) && p[2] == z,
                      "pixel (%u, %u): (%f, %f, %f), expected (%f, %f, %f)", u, v,
                      (double)p[0], (double)p[1], (double)p[2], (double)x, (double)y,
                      (double)z);
                n_valid++;
            } else {
                CHECK(valid[i] == 0, "pixel (%u, %u) without depth is not valid", u, v);
                CHECK(isnan(p[0]) && isnan(p[1]) && isnan(p[2]),
                      "pixel (%u, %u) without depth is NaN, not a point", u, v);
                n_invalid++;
            }
        }
    }
    CHECK(n_valid > 0 && n_invalid > 0, "%zu valid and %zu invalid pixels", n_valid, n_invalid);
    /* Without a mask the NaNs tell the same. */
    EXPECT_STATUS(dear_frame_point_cloud(frame, xyz, 3 * pixels, NULL, 0), DEAR_OK);
    printf("points valid=%zu invalid=%zu\n", n_valid, n_invalid);
    free(xyz);
    free(valid);
    dear_frame_release(frame);
    dear_client_free(client);
    ok("point cloud: every pixel's point from the header's intrinsics, invalid depth masked");
}

/* Brown-Conrady distortion of a normalised point (OpenCV's model), in double. */
static void distort(const float *d, double x, double y, double *xd, double *yd) {
    double r2 = x * x + y * y;
    double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
    *xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
    *yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
}

static void distorted(const char *service, char **coefficients) {
    dear_client *client = NULL;
    EXPECT_STATUS(dear_client_connect(service, &client), DEAR_OK);
    dear_frame *frame = NULL;
    EXPECT_STATUS(dear_client_wait(client, 20000, &frame), DEAR_OK);
    const dear_header *h = dear_frame_header(frame);
    CHECK(h->rgb_camera_model == DEAR_CAMERA_MODEL_BROWN_CONRADY, "model %u",
          (unsigned)h->rgb_camera_model);
    for (int i = 0; i < 5; i++) {
        float want = strtof(coefficients[i], NULL);
        CHECK(h->rgb_distortion[i] == want, "coefficient %d: %g, capture.json %g", i,
              (double)h->rgb_distortion[i], (double)want);
    }
    size_t pixels = (size_t)h->width * h->height;
    float *xyz = malloc(3 * pixels * sizeof(float));
    uint8_t *valid = malloc(pixels);
    CHECK(xyz && valid, "memory");
    EXPECT_STATUS(dear_frame_point_cloud(frame, xyz, 3 * pixels, valid, pixels), DEAR_OK);
    const float *depth = dear_frame_depth(frame, NULL);
    size_t n_valid = 0, bent = 0;
    double worst = 0.0;
    for (uint32_t v = 0; v < h->height; v++) {
        for (uint32_t u = 0; u < h->width; u++) {
            size_t i = (size_t)v * h->width + u;
            const float *p = xyz + 3 * i;
            if (!(depth[i] > 0.0f && isfinite(depth[i]))) {
                CHECK(valid[i] == 0 && isnan(p[2]), "pixel (%u, %u) without depth", u, v);
                continue;
            }
            CHECK(valid[i] == 1 && p[2] == depth[i], "pixel (%u, %u): z is the depth", u, v);
            double xd, yd;
            distort(h->rgb_distortion, (double)p[0] / p[2], (double)p[1] / p[2], &xd, &yd);
            double du = xd * h->rgb_fx + h->rgb_cx - u, dv = yd * h->rgb_fy + h->rgb_cy - v;
            double e = fabs(du) > fabs(dv) ? fabs(du) : fabs(dv);
            worst = e > worst ? e : worst;
            /* How far the pinhole ray would have put the point, in pixels. */
            double pu = (double)p[0] / p[2] * h->rgb_fx + h->rgb_cx - u;
            bent += fabs(pu) > 0.5;
            n_valid++;
        }
    }
    CHECK(n_valid > 0, "valid pixels");
    /* float32 points: a few thousandths of a pixel. */
    CHECK(worst < 1e-3, "a point reprojects %g px from its pixel", worst);
    CHECK(bent > n_valid / 10, "the distortion moved only %zu of %zu points", bent, n_valid);
    printf("distorted: %zu points, worst reprojection %.2g px, %zu moved > 0.5 px\n", n_valid,
           worst, bent);
    free(xyz);
    free(valid);
    dear_frame_release(frame);
    dear_client_free(client);
    ok("distorted point cloud: the header's coefficients, every point back on its pixel");
}

/* A reconnecting client outlives its daemon: after "ready" the test kills the daemon and
   starts another on the service; the channel stalls, is connected again, and frames come. */
static void reconnecting(const char *service) {
    dear_client *client = (dear_client *)0x1;
    EXPECT_STATUS(dear_client_connect_reconnecting(NULL, 0, &client), DEAR_INVALID_ARGUMENT);
    CHECK(client == NULL && mentions("dear_client_connect_reconnecting"), "names the function");
    CHECK(dear_client_reconnects(NULL) == 0, "no reconnections of no client");
    EXPECT_STATUS(dear_client_connect_reconnecting(service, 500, &client), DEAR_OK);
    dear_frame *frame = NULL;
    EXPECT_STATUS(dear_client_wait(client, 20000, &frame), DEAR_OK);
    uint64_t first_run = dear_frame_header(frame)->run_id;
    dear_frame_release(frame);
    CHECK(dear_client_reconnects(client) == 0, "a healthy channel is kept");
    printf("ready\n");
    fflush(stdout);
    /* Up to 60 s for the test to replace the daemon and for a frame of the new one. */
    int got = 0;
    for (int i = 0; i < 600 && !got; i++) {
        dear_status status = dear_client_wait(client, 100, &frame);
        CHECK(status == DEAR_OK || status == DEAR_TIMEOUT, "only frames and timeouts");
        if (status == DEAR_OK) {
            got = dear_frame_header(frame)->run_id != first_run;
            dear_frame_release(frame);
        }
    }
    CHECK(got, "a frame of the new daemon");
    CHECK(dear_client_reconnects(client) >= 1, "the channel was connected again");
    printf("reconnects: %llu\n", (unsigned long long)dear_client_reconnects(client));
    dear_client_free(client);
    ok("reconnecting: the stream outlives its daemon");
}

int main(int argc, char **argv) {
    if (argc == 8 && strcmp(argv[1], "distorted") == 0) {
        distorted(argv[2], argv + 3);
        printf("%d checks passed\n", checks);
        return 0;
    }
    if (argc != 3) {
        fprintf(stderr, "usage: %s arguments|timeout|frames|points|reconnecting SERVICE\n", argv[0]);
        return 2;
    }
    if (strcmp(argv[1], "arguments") == 0) {
        arguments(argv[2]);
    } else if (strcmp(argv[1], "timeout") == 0) {
        timeout(argv[2]);
    } else if (strcmp(argv[1], "frames") == 0) {
        frames(argv[2]);
    } else if (strcmp(argv[1], "points") == 0) {
        points(argv[2]);
    } else if (strcmp(argv[1], "reconnecting") == 0) {
        reconnecting(argv[2]);
    } else {
        fprintf(stderr, "unknown mode %s\n", argv[1]);
        return 2;
    }
    printf("%d checks passed\n", checks);
    return 0;
}
