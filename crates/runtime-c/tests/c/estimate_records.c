/* Estimates records with the runtime's C API, as a C firmware or tool
 * would: usage `estimate_records BLOB RECORDS WINDOW EVERY`. RECORDS is text: a line
 * "R N NU NY", then R*N lines of NU inputs and NY outputs. For each record
 * it prints "rc theta... widths... intervals ood distance threshold
 * untransformed input-mask interval-rc (lower upper)... draws-rc draws..."
 * (three draws of the posterior, seed 5, the record's number). Then it slides
 * a window of WINDOW samples over the records before the last, one after
 * another, and prints "window END rc theta... ood input-mask" every EVERY
 * samples. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "twostage_rt.h"

static unsigned char *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *bytes = malloc((size_t)size);
    if (bytes && fread(bytes, 1, (size_t)size, f) != (size_t)size) {
        free(bytes);
        bytes = NULL;
    }
    fclose(f);
    *len = (size_t)size;
    return bytes;
}

int main(int argc, char **argv) {
    if (argc != 5) {
        fprintf(stderr, "usage: %s BLOB RECORDS WINDOW EVERY\n", argv[0]);
        return 2;
    }
    size_t window = (size_t)strtoul(argv[3], NULL, 10), every = (size_t)strtoul(argv[4], NULL, 10);
    size_t len = 0;
    unsigned char *blob = read_file(argv[1], &len);
    if (!blob) {
        fprintf(stderr, "cannot read %s\n", argv[1]);
        return 2;
    }

    /* A damaged copy is refused with a reason. */
    unsigned char *damaged = malloc(len);
    memcpy(damaged, blob, len);
    damaged[len - 1] ^= 0x40;
    ts_estimator refused = {0};
    int rc = ts_estimator_load(&refused, damaged, len);
    printf("damaged %d %s\n", rc, ts_error_message(rc));
    free(damaged);

    ts_estimator est = {0};
    rc = ts_estimator_load(&est, blob, len);
    if (rc != TS_OK) {
        fprintf(stderr, "load: %s\n", ts_error_message(rc));
        return 1;
    }
    size_t q = ts_parameters(&est), nu = ts_inputs(&est), ny = ts_outputs(&est);
    size_t work_len = ts_workspace_len(&est);
    double *work = malloc(work_len * sizeof(double));
    double *theta = malloc(q * sizeof(double));
    double *widths = malloc(q * sizeof(double));
    double *lower = malloc(q * sizeof(double));
    double *upper = malloc(q * sizeof(double));
    double *draws = malloc(3 * q * sizeof(double));
    double u[16], y[16];

    FILE *records = fopen(argv[2], "r");
    size_t r_count, n, file_nu, file_ny;
    if (!records || fscanf(records, "%zu %zu %zu %zu", &r_count, &n, &file_nu, &file_ny) != 4 ||
        file_nu != nu || file_ny != ny || nu > 16 || ny > 16) {
        fprintf(stderr, "bad records file\n");
        return 2;
    }
    double *kept = malloc(r_count * n * (nu + ny) * sizeof(double));
    int after_finish = 1;
    ts_stream stream;
    rc = ts_stream_start(&stream, &est, work, work_len);
    if (rc != TS_OK) {
        fprintf(stderr, "start: %s\n", ts_error_message(rc));
        return 1;
    }
    for (size_t r = 0; r < r_count; r++) {
        for (size_t t = 0; t < n; t++) {
            for (size_t j = 0; j < nu; j++) if (fscanf(records, "%lf", &u[j]) != 1) return 2;
            for (size_t j = 0; j < ny; j++) if (fscanf(records, "%lf", &y[j]) != 1) return 2;
            memcpy(kept + (r * n + t) * (nu + ny), u, nu * sizeof(double));
            memcpy(kept + (r * n + t) * (nu + ny) + nu, y, ny * sizeof(double));
            rc = ts_stream_push(&stream, u, y);
            if (rc != TS_OK) break;
        }
        ts_assessment a;
        if (rc == TS_OK) rc = ts_stream_finish(&stream, theta, q, widths, q, &a);
        printf("%d", rc);
        if (rc == TS_OK) {
            for (size_t j = 0; j < q; j++) printf(" %.17g", theta[j]);
            for (size_t j = 0; j < q; j++) printf(" %.17g", widths[j]);
            printf(" %d %d %.17g %.17g %u %llu", a.intervals, a.out_of_distribution,
                   a.feature_distance, a.distance_threshold, (unsigned)a.untransformed_samples,
                   (unsigned long long)a.input_outside_family);
            /* The interval as the host writes it: inside the prior's box. */
            int bounds = ts_interval(&est, theta, widths, lower, upper, q);
            printf(" %d", bounds);
            for (size_t j = 0; j < q; j++) printf(" %.17g %.17g", lower[j], upper[j]);
            /* Three draws from the posterior, as the host's record r of seed 5. */
            int drawn = ts_stream_finish_draws(&stream, theta, q, draws, 3 * q, 5, r, NULL);
            printf(" %d", drawn);
            for (size_t k = 0; k < 3 * q; k++) printf(" %.17g", draws[k]);
        } else {
            printf(" %s", ts_error_message(rc));
        }
        printf("\n");
        /* A finished stream goes on (finish estimates the samples so far). */
        if (r == 0) after_finish = ts_stream_push(&stream, u, y);
        ts_stream_reset(&stream);
    }
    printf("after-finish %d\n", after_finish);
    /* An empty stream is too short to finish. */
    printf("empty %d\n", ts_stream_finish(&stream, theta, q, NULL, 0, NULL));

    /* A window too short for one regression is refused. */
    printf("short window %d\n", ts_window_start(&stream, &est, 3, work, work_len));
    size_t window_len = ts_window_workspace_len(&est, window);
    double *window_work = malloc(window_len * sizeof(double));
    rc = ts_window_start(&stream, &est, window, window_work, window_len);
    if (rc != TS_OK) {
        fprintf(stderr, "window: %s\n", ts_error_message(rc));
        return 1;
    }
    for (size_t t = 0; t < (r_count - 1) * n; t++) {
        rc = ts_stream_push(&stream, kept + t * (nu + ny), kept + t * (nu + ny) + nu);
        if (rc != TS_OK) break;
        if ((t + 1) % every != 0) continue;
        ts_assessment a;
        rc = ts_stream_finish(&stream, theta, q, NULL, 0, &a);
        printf("window %zu %d", t + 1, rc);
        if (rc == TS_OK) {
            for (size_t j = 0; j < q; j++) printf(" %.17g", theta[j]);
            printf(" %d %llu", a.out_of_distribution, (unsigned long long)a.input_outside_family);
        }
        printf("\n");
    }
    free(window_work);
    free(kept);
    free(work);
    free(theta);
    free(widths);
    free(lower);
    free(upper);
    free(draws);
    free(blob);
    return 0;
}
