/* Count the MPI calls of a process (PMPI interposition): what `pmpm bench ranks --count-calls`
 * reports as the synchronisation points per step.  Build: see count_mpi_calls.sh.
 *
 * Every call that can make a rank wait for another is counted by name: the blocking
 * collectives, MPI_Wait/Waitall (the end of a halo or migration exchange) and MPI_File_*_all
 * (collective I/O).  pmpm's own waits (decomposition/waiting.py) test requests in a loop; a
 * wait is counted once, at its first MPI_Testall of a new request set, as "wait(test loop)".
 * At MPI_Finalize each rank writes one line "rank R: name count, ..." to the file named by
 * PMPM_MPI_CALLS (nothing without it).
 */
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NAMES 32
static const char *names[NAMES];
static long counts[NAMES];
static int used;

static void count(const char *name) {
    for (int i = 0; i < used; i++)
        if (names[i] == name) { counts[i]++; return; }
    if (used < NAMES) { names[used] = name; counts[used++] = 1; }
}

#define WRAP(ret, fn, params, args) \
    ret fn params { count(#fn); return P##fn args; }

WRAP(int, MPI_Allreduce, (const void *s, void *r, int n, MPI_Datatype t, MPI_Op op, MPI_Comm c), (s, r, n, t, op, c))
WRAP(int, MPI_Iallreduce, (const void *s, void *r, int n, MPI_Datatype t, MPI_Op op, MPI_Comm c, MPI_Request *q), (s, r, n, t, op, c, q))
WRAP(int, MPI_Bcast, (void *b, int n, MPI_Datatype t, int root, MPI_Comm c), (b, n, t, root, c))
WRAP(int, MPI_Barrier, (MPI_Comm c), (c))
WRAP(int, MPI_Allgather, (const void *s, int sn, MPI_Datatype st, void *r, int rn, MPI_Datatype rt, MPI_Comm c), (s, sn, st, r, rn, rt, c))
WRAP(int, MPI_Gather, (const void *s, int sn, MPI_Datatype st, void *r, int rn, MPI_Datatype rt, int root, MPI_Comm c), (s, sn, st, r, rn, rt, root, c))
WRAP(int, MPI_Alltoall, (const void *s, int sn, MPI_Datatype st, void *r, int rn, MPI_Datatype rt, MPI_Comm c), (s, sn, st, r, rn, rt, c))
WRAP(int, MPI_Exscan, (const void *s, void *r, int n, MPI_Datatype t, MPI_Op op, MPI_Comm c), (s, r, n, t, op, c))
WRAP(int, MPI_Sendrecv, (const void *s, int sn, MPI_Datatype st, int d, int stag, void *r, int rn, MPI_Datatype rt, int so, int rtag, MPI_Comm c, MPI_Status *sts), (s, sn, st, d, stag, r, rn, rt, so, rtag, c, sts))
WRAP(int, MPI_Send, (const void *b, int n, MPI_Datatype t, int d, int tag, MPI_Comm c), (b, n, t, d, tag, c))
WRAP(int, MPI_Recv, (void *b, int n, MPI_Datatype t, int s, int tag, MPI_Comm c, MPI_Status *st), (b, n, t, s, tag, c, st))
WRAP(int, MPI_Mprobe, (int s, int tag, MPI_Comm c, MPI_Message *m, MPI_Status *st), (s, tag, c, m, st))
WRAP(int, MPI_Alltoallv, (const void *s, const int sc[], const int sd[], MPI_Datatype st, void *r, const int rc[], const int rd[], MPI_Datatype rt, MPI_Comm c), (s, sc, sd, st, r, rc, rd, rt, c))
WRAP(int, MPI_Wait, (MPI_Request *q, MPI_Status *st), (q, st))
WRAP(int, MPI_Waitall, (int n, MPI_Request q[], MPI_Status st[]), (n, q, st))
WRAP(int, MPI_Isend, (const void *b, int n, MPI_Datatype t, int d, int tag, MPI_Comm c, MPI_Request *q), (b, n, t, d, tag, c, q))
WRAP(int, MPI_File_write_at_all, (MPI_File f, MPI_Offset o, const void *b, int n, MPI_Datatype t, MPI_Status *s), (f, o, b, n, t, s))
WRAP(int, MPI_File_read_at_all, (MPI_File f, MPI_Offset o, void *b, int n, MPI_Datatype t, MPI_Status *s), (f, o, b, n, t, s))
WRAP(int, MPI_File_set_size, (MPI_File f, MPI_Offset o), (f, o))
WRAP(int, MPI_File_open, (MPI_Comm c, const char *p, int a, MPI_Info i, MPI_File *f), (c, p, a, i, f))

/* a test loop over the same requests counts once (mpi4py passes a fresh array each call, so
 * the first request's handle, not the array, tells one wait from the next) */
static MPI_Request last_first = MPI_REQUEST_NULL;
int MPI_Testall(int n, MPI_Request q[], int *flag, MPI_Status st[]) {
    MPI_Request first = n > 0 ? q[0] : MPI_REQUEST_NULL;
    if (first == MPI_REQUEST_NULL || first != last_first) count("wait(test loop)");
    int rc = PMPI_Testall(n, q, flag, st);
    last_first = *flag ? MPI_REQUEST_NULL : first;
    return rc;
}

int MPI_Finalize(void) {
    const char *path = getenv("PMPM_MPI_CALLS");
    if (path) {
        int rank;
        PMPI_Comm_rank(MPI_COMM_WORLD, &rank);
        FILE *f = fopen(path, "a");
        if (f) {
            fprintf(f, "rank %d:", rank);
            for (int i = 0; i < used; i++) fprintf(f, " %s %ld%s", names[i], counts[i], i + 1 < used ? "," : "");
            fprintf(f, "\n");
            fclose(f);
        }
    }
    return PMPI_Finalize();
}
