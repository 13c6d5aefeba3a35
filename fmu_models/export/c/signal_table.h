/* A signal table read from an FMU's resources: the outputs of a table model
 * (`table` in the model's descriptor, fmu_core.h), model-independent like the rest of this
 * folder. The table is data from whoever packed the FMU: its file is checked
 * whole when it is loaded (size, shape, finite values, times that never go
 * back) and bounded (TABLE_MAX_ROWS), before a value of it is used.
 *
 * The file, resources/signal_table.bin, written by
 * fmu_models/models/signal_table.py (little-endian, as every platform the
 * FMUs are built for):
 *   "FNNTAB01"                    8 bytes
 *   rows, columns                 2 x uint64
 *   interpolation per column      columns x uint8 (0: hold, 1: linear)
 *   outside                       uint8 (0: hold the first / last row, 1: refuse)
 *   padding                       zeros to a multiple of 8 bytes
 *   times                         rows x float64
 *   values                        rows x columns float64, row after row
 *
 * The values at time t are those of cosim/scenario/signal_table.py (docs/cosim.md, "The
 * signal table"): row i is the last whose time is <= t, a time within 1e-9
 * relative of t counting as <= t (Python's math.isclose); hold gives row i,
 * linear row i + w (row i+1 - row i) with w = max(0, (t - t_i) / (t_i+1 - t_i)),
 * the same operations in the same order, so the same doubles. */
#ifndef SIGNAL_TABLE_H
#define SIGNAL_TABLE_H

#include <stddef.h>

#define TABLE_FILE "signal_table.bin"
#define TABLE_MAX_ROWS 10000000u /* cosim.limits.MAX_TABLE_ROWS */
#define TABLE_MAX_BYTES 1073741824.0 /* the file: 8 bytes a number, 4x a CSV of MAX_TABLE_BYTES at most */

typedef struct {
    size_t rows, columns;
    int refuse_outside;
    unsigned char *linear; /* per column */
    double *time;          /* rows */
    double *values;        /* rows x columns */
} SignalTable;

/* Load the table from the folder `resources` (an FMI 2.0 "file:" URI when
 * `is_uri`, else an FMI 3.0 path), expecting `columns` columns. 0 on success;
 * else -1 with a one-line reason in `error`. */
int table_load(SignalTable *table, const char *resources, int is_uri, size_t columns, char *error, size_t size);
void table_free(SignalTable *table);
/* Whether t lies outside the recorded times [first, last] (within 1e-9 relative). */
int table_outside(const SignalTable *table, double t);
/* The values of every column at t, into y. */
void table_values(const SignalTable *table, double t, double *y);

#endif
