/* A signal table read from an FMU's resources; see signal_table.h. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "signal_table.h"

static const char MAGIC[8] = {'F', 'N', 'N', 'T', 'A', 'B', '0', '1'};

/* The file path of the table in `resources`: an FMI 2.0 URI ("file:///a/b",
 * "file:/a/b", percent-encoded) decoded to a path, or an FMI 3.0 path. */
static int table_path(const char *resources, int is_uri, char *path, size_t size) {
    char folder[4096];
    size_t n = 0;
    if (!resources) return -1;
    if (is_uri) {
        if (strncmp(resources, "file:", 5) != 0) return -1;
        const char *p = resources + 5;
        if (strncmp(p, "///", 3) == 0) p += 2;          /* file:///a -> /a */
        else if (strncmp(p, "//localhost/", 12) == 0) p += 11;
        for (; *p && n + 1 < sizeof folder; p++) {
            unsigned hex;
            if (*p == '%' && p[1] && p[2] && sscanf(p + 1, "%2x", &hex) == 1) {
                folder[n++] = (char)hex;
                p += 2;
            } else {
                folder[n++] = *p;
            }
        }
        folder[n] = '\0';
    } else {
        n = (size_t)snprintf(folder, sizeof folder, "%s", resources);
        if (n >= sizeof folder) return -1;
    }
    const char *sep = (n > 0 && folder[n - 1] == '/') ? "" : "/";
    return (size_t)snprintf(path, size, "%s%s%s", folder, sep, TABLE_FILE) < size ? 0 : -1;
}

void table_free(SignalTable *table) {
    free(table->linear);
    free(table->time);
    free(table->values);
    memset(table, 0, sizeof *table);
}

int table_load(SignalTable *table, const char *resources, int is_uri, size_t columns, char *error, size_t size) {
    char path[4200];
    uint64_t shape[2];
    memset(table, 0, sizeof *table);
    if (table_path(resources, is_uri, path, sizeof path) != 0) {
        snprintf(error, size, "signal table: resources location \"%.200s\" is no folder path or file: URI",
                 resources ? resources : "(null)");
        return -1;
    }
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(error, size, "signal table: cannot open %.300s", path);
        return -1;
    }
    char magic[8];
    const char *why = NULL;
    if (fread(magic, 1, 8, f) != 8 || memcmp(magic, MAGIC, 8) != 0 || fread(shape, 8, 2, f) != 2) {
        why = "not a signal table file (expected FNNTAB01)";
    } else if (shape[1] != columns) {
        why = "its number of columns is not this FMU's outputs'";
    } else if (shape[0] < 1 || shape[0] > TABLE_MAX_ROWS) {
        why = "its number of rows is 0 or beyond 10^7";
    }
    const size_t flags = columns + 1, pad = (8 - (24 + flags) % 8) % 8;
    long length = -1;
    if (!why && fseek(f, 0, SEEK_END) == 0) length = ftell(f);
    if (!why && (length < 0 || (double)length > TABLE_MAX_BYTES ||
                 (size_t)length != 24 + flags + pad + 8 * (size_t)shape[0] * (columns + 1) ||
                 fseek(f, 24, SEEK_SET) != 0)) {
        why = "its size is not the one its header gives, or beyond 1 GiB";
    }
    if (!why) {
        const size_t rows = (size_t)shape[0];
        table->rows = rows;
        table->columns = columns;
        table->linear = (unsigned char *)malloc(flags);
        table->time = (double *)malloc(rows * sizeof(double));
        table->values = (double *)malloc(rows * columns * sizeof(double) + 1);
        unsigned char padding[8];
        if (!table->linear || !table->time || !table->values) {
            why = "out of memory";
        } else if (fread(table->linear, 1, flags, f) != flags || fread(padding, 1, pad, f) != pad ||
                   fread(table->time, 8, rows, f) != rows ||
                   fread(table->values, 8, rows * columns, f) != rows * columns || fgetc(f) != EOF) {
            why = "its size is not the one its header gives";
        } else {
            table->refuse_outside = table->linear[columns] == 1;
            for (size_t j = 0; j <= columns && !why; j++)
                if (table->linear[j] > 1) why = "an interpolation or outside flag that is neither 0 nor 1";
            for (size_t i = 0; i < rows && !why; i++) {
                if (!isfinite(table->time[i])) why = "a time that is not finite";
                else if (i > 0 && table->time[i] < table->time[i - 1]) why = "times that go back";
            }
            for (size_t k = 0; k < rows * columns && !why; k++)
                if (!isfinite(table->values[k])) why = "a value that is not finite";
        }
    }
    fclose(f);
    if (why) {
        snprintf(error, size, "signal table %.300s refused: %s", path, why);
        table_free(table);
        return -1;
    }
    return 0;
}

static int close_to(double a, double b) { /* math.isclose(a, b, rel_tol=1e-9) */
    return a == b || fabs(a - b) <= 1e-9 * fmax(fabs(a), fabs(b));
}

/* The last row whose time is <= t (or within 1e-9 relative of it), -1 before the first. */
static long row_at(const SignalTable *table, double t) {
    size_t lo = 0, hi = table->rows; /* first row with time > t: numpy's searchsorted(side="right") */
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (table->time[mid] <= t) lo = mid + 1;
        else hi = mid;
    }
    long i = (long)lo - 1;
    while ((size_t)(i + 1) < table->rows && close_to(table->time[i + 1], t)) i++;
    return i;
}

int table_outside(const SignalTable *table, double t) {
    return (t < table->time[0] && !close_to(t, table->time[0])) ||
           (t > table->time[table->rows - 1] && !close_to(t, table->time[table->rows - 1]));
}

void table_values(const SignalTable *table, double t, double *y) {
    const long i = row_at(table, t), last = (long)table->rows - 1;
    const size_t n = table->columns;
    const double *row = table->values + (size_t)(i < 0 ? 0 : i) * n;
    for (size_t j = 0; j < n; j++) {
        if (i < 0 || i == last || !table->linear[j]) {
            y[j] = row[j];
        } else {
            const double t0 = table->time[i], t1 = table->time[i + 1];
            double w = (t - t0) / (t1 - t0);
            if (w < 0.0) w = 0.0;  /* t within 1e-9 below row i's time: that row */
            y[j] = row[j] + w * (row[n + j] - row[j]);
        }
    }
}
