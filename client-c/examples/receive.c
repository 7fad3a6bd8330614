/*
 * receive: waits for COUNT frames of a deard frame service through libdear_client and prints
 * one line per frame:
 *
 *     frame <frame_id> <width>x<height> valid=<pixels with depth > 0> run=<run_id, hex> seq=<sequence>
 *
 * Usage: receive [SERVICE [COUNT [TIMEOUT_MS]]]   (defaults: dear/cam0/frames, 5, 5000)
 * Exit status: 0 after COUNT frames; 1 on a failure, 3 when no frame came within TIMEOUT_MS
 * (both print dear_last_error() to stderr); 2 on bad arguments.
 *
 * Build (README, "C"):
 *     cargo build --release -p dear-client-c
 *     cc -O2 -Iclient-c/include client-c/examples/receive.c target/release/libdear_client.a \
 *        -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o receive
 * The service is found under $DEAR_IOX2_ROOT (else /dev/shm/dear), as by every DEAR client.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>

#include "dear_client.h"

static int fail(const char *what, dear_status status) {
    fprintf(stderr, "receive: %s: %s: %s\n", what, dear_status_name(status), dear_last_error());
    return status == DEAR_TIMEOUT ? 3 : 1;
}

static int parse_unsigned(const char *text, unsigned long max, unsigned long *out) {
    char *end;
    unsigned long value = strtoul(text, &end, 10);
    if (*text == '\0' || *end != '\0' || value > max) return 0;
    *out = value;
    return 1;
}

int main(int argc, char **argv) {
    const char *service = argc > 1 ? argv[1] : "dear/cam0/frames";
    unsigned long count = 5, timeout_ms = 5000;
    if (argc > 4 || (argc > 2 && !parse_unsigned(argv[2], 1000000000UL, &count)) ||
        (argc > 3 && !parse_unsigned(argv[3], UINT32_MAX, &timeout_ms))) {
        fprintf(stderr, "usage: %s [SERVICE [COUNT [TIMEOUT_MS]]]\n", argv[0]);
        return 2;
    }

    dear_client *client = NULL;
    dear_status status = dear_client_connect(service, &client);
    if (status != DEAR_OK) return fail("connect", status);

    int rc = 0;
    unsigned long received = 0;
    while (received < count) {
        dear_frame *frame = NULL;
        status = dear_client_wait(client, (uint32_t)timeout_ms, &frame);
        if (status == DEAR_BAD_FRAME || status == DEAR_INTERRUPTED) {
            /* A corrupt sample was dropped, or a signal woke us: the stream goes on. */
            fprintf(stderr, "receive: %s: %s\n", dear_status_name(status), dear_last_error());
            continue;
        }
        if (status != DEAR_OK) {
            rc = fail("wait", status);
            break;
        }
        const dear_header *h = dear_frame_header(frame);
        size_t n = 0;
        const float *depth = dear_frame_depth(frame, &n);
        if (h == NULL || depth == NULL || n != (size_t)h->width * h->height) {
            fprintf(stderr, "receive: inconsistent frame: %s\n", dear_last_error());
            dear_frame_release(frame);
            rc = 1;
            break;
        }
        size_t valid = 0;
        for (size_t i = 0; i < n; i++) valid += depth[i] > 0.0f;
        printf("frame %" PRIu64 " %" PRIu32 "x%" PRIu32 " valid=%zu run=%016" PRIx64
               " seq=%" PRIu64 "\n",
               h->frame_id, h->width, h->height, valid, h->run_id, h->sequence);
        fflush(stdout);
        /* Give the sample back at once: a client may hold only DEAR_MAX_HELD_FRAMES. */
        dear_frame_release(frame);
        received++;
    }
    dear_client_free(client);
    return rc;
}
