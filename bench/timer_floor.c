/* The machine's timing floor: a periodic loop that does no work, the way the product's loop
 * waits (sleep until spin_us before the deadline, then spin on the clock), in C without Python.
 * Whatever misses it shows, no code of ours can remove on this host (bench/timer_floor.py).
 *
 *   timer_floor RATE_HZ SECONDS SPIN_US TOLERANCE
 * prints one line of JSON: cycles, misses (later than TOLERANCE x period), lateness histogram
 * in 1 us bins up to 5 ms (sparse: [bin, count] pairs) and the largest lateness in ns. */
#define _GNU_SOURCE
#include <sched.h>
#include <stdint.h>
#include <sys/mman.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define N_BINS 5001

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 5) {
        fprintf(stderr, "usage: timer_floor RATE_HZ SECONDS SPIN_US TOLERANCE\n");
        return 2;
    }
    double rate = atof(argv[1]), seconds = atof(argv[2]), spin_us = atof(argv[3]);
    double tolerance = atof(argv[4]);
    if (!(rate > 0 && seconds > 0 && spin_us >= 0 && tolerance > 0)) {
        fprintf(stderr, "timer_floor: RATE_HZ, SECONDS and TOLERANCE must be > 0, SPIN_US >= 0\n");
        return 2;
    }
    int64_t period = (int64_t)(1e9 / rate), spin = (int64_t)(spin_us * 1e3);
    if (spin > period / 2) spin = period / 2;
    int64_t tol = (int64_t)(tolerance * period), cycles = (int64_t)(seconds * rate);
    /* The same hygiene the product's loop tries (rt_hygiene.realtime_thread): SCHED_FIFO 80
     * and locked memory; refused (not root) leaves the ordinary scheduler, reported. */
    struct sched_param sp = {.sched_priority = 80};
    int fifo = sched_setscheduler(0, SCHED_FIFO, &sp) == 0;
    int locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    static int64_t hist[N_BINS];
    int64_t misses = 0, worst = 0, deadline = now_ns() + period;
    for (int64_t i = 0; i < cycles; ++i) {
        int64_t t = now_ns();
        if (deadline - t > spin) {
            int64_t wake = deadline - spin;
            struct timespec ts = {wake / 1000000000LL, wake % 1000000000LL};
            clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
        }
        while ((t = now_ns()) < deadline) { }
        int64_t late = t - deadline;
        if (late > worst) worst = late;
        if (late > tol) ++misses;
        int64_t bin = late / 1000;
        hist[bin < N_BINS ? bin : N_BINS - 1]++;
        deadline += period;
        if (t - deadline > period) deadline = t + period;   /* behind: restart, like the loop */
    }
    printf("{\"fifo\": %d, \"mlockall\": %d, \"cycles\": %lld, \"misses\": %lld, \"max_late_ns\": %lld, \"hist\": [",
           fifo, locked, (long long)cycles, (long long)misses, (long long)worst);
    int first = 1;
    for (int b = 0; b < N_BINS; ++b) {
        if (!hist[b]) continue;
        printf("%s[%d, %lld]", first ? "" : ", ", b, (long long)hist[b]);
        first = 0;
    }
    printf("]}\n");
    return 0;
}
