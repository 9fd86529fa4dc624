/* Counts the ray queries Mitsuba 3 hands to Embree, and optionally keeps some of its rays.
 *
 * Preloaded into a Mitsuba render by `scripts/mitsuba_rays.py` (which builds it with gcc):
 * Mitsuba's wheels link a private Embree 3 (`libembree3.so` beside `libmitsuba.so`) whose API
 * lives in the C++ namespace `mitsuba`, so the functions wrapped here carry those mangled
 * names. Each wrapper counts the rays of the call (a packet call counts its valid lanes) and
 * forwards to the real function, looked up in the library named by `EMBREE_LIB` (it is
 * loaded by Python with local symbols, so `RTLD_NEXT` does not see it).
 *
 * Environment:
 *   EMBREE_LIB       path of Mitsuba's libembree3.so (required)
 *   RAYCOUNT_OUT     file the counts are appended to at exit, one line per process that
 *                    traced anything: `intersect N occluded N packet_calls N lanes_in_dump N`
 *   DUMP_FILE        optional: rays of the first thread's 16-wide closest-hit calls, six
 *                    little-endian f32 a ray (origin, direction), valid lanes in call order
 *   DUMP_EVERY       keep every DUMP_EVERY-th such call (default 1)
 *   DUMP_RAYS        at most this many rays (default 4000000)
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>

static unsigned long long n_intersect, n_occluded, n_calls;

static void *embree(void) {
    static void *h;
    if (!h) {
        const char *path = getenv("EMBREE_LIB");
        h = path ? dlopen(path, RTLD_LAZY | RTLD_NOLOAD) : NULL;
        if (!h) {
            fprintf(stderr, "embree_count: EMBREE_LIB (%s) is not loaded\n", path ? path : "unset");
            abort();
        }
    }
    return h;
}

static void *real(const char *name) {
    void *f = dlsym(embree(), name);
    if (!f) {
        fprintf(stderr, "embree_count: %s not found\n", name);
        abort();
    }
    return f;
}

/* The dump: the first thread that traces a 16-wide packet owns it. */
static pthread_mutex_t dump_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_t dump_owner;
static int dump_state; /* 0 undecided, 1 dumping, 2 off */
static float *dump_buf;
static size_t dump_len, dump_cap, dump_every = 1;
static unsigned long long dump_calls;

static void dump_packet16(const int *valid, const float *rayhit) {
    pthread_mutex_lock(&dump_lock);
    if (dump_state == 0) {
        const char *file = getenv("DUMP_FILE");
        dump_state = file ? 1 : 2;
        if (file) {
            dump_owner = pthread_self();
            dump_cap = getenv("DUMP_RAYS") ? strtoull(getenv("DUMP_RAYS"), NULL, 10) : 4000000;
            dump_every = getenv("DUMP_EVERY") ? strtoull(getenv("DUMP_EVERY"), NULL, 10) : 1;
            if (dump_every == 0)
                dump_every = 1;
            dump_buf = malloc(dump_cap * 6 * sizeof(float));
            if (!dump_buf)
                dump_state = 2;
        }
    }
    int mine = dump_state == 1 && pthread_equal(dump_owner, pthread_self());
    pthread_mutex_unlock(&dump_lock);
    if (!mine || dump_calls++ % dump_every != 0)
        return;
    /* RTCRayHit16 begins with RTCRay16: org_x[16] org_y[16] org_z[16] tnear[16] dir_x[16]
       dir_y[16] dir_z[16] ... */
    for (int k = 0; k < 16 && dump_len < dump_cap; k++) {
        if (!valid[k])
            continue;
        float *o = dump_buf + 6 * dump_len++;
        o[0] = rayhit[k];
        o[1] = rayhit[16 + k];
        o[2] = rayhit[32 + k];
        o[3] = rayhit[64 + k];
        o[4] = rayhit[80 + k];
        o[5] = rayhit[96 + k];
    }
}

static int lanes(const int *valid, int width) {
    int n = 0;
    for (int k = 0; k < width; k++)
        n += valid[k] != 0;
    return n;
}

typedef void (*single_fn)(void *, void *, void *);
typedef void (*packet_fn)(const int *, void *, void *, void *);

#define SINGLE(mangled, counter)                                                    \
    void mangled(void *scene, void *context, void *ray) {                           \
        static single_fn f;                                                         \
        if (!f)                                                                     \
            f = (single_fn)real(#mangled);                                          \
        __atomic_fetch_add(&counter, 1, __ATOMIC_RELAXED);                          \
        f(scene, context, ray);                                                     \
    }

#define PACKET(mangled, width, counter, dump)                                       \
    void mangled(const int *valid, void *scene, void *context, void *ray) {         \
        static packet_fn f;                                                         \
        if (!f)                                                                     \
            f = (packet_fn)real(#mangled);                                          \
        __atomic_fetch_add(&counter, lanes(valid, width), __ATOMIC_RELAXED);        \
        __atomic_fetch_add(&n_calls, 1, __ATOMIC_RELAXED);                          \
        if (dump)                                                                   \
            dump_packet16(valid, (const float *)ray);                               \
        f(valid, scene, context, ray);                                              \
    }

/* rtcIntersect1 / rtcOccluded1 (scalar variants), rtcIntersect{4,8,16} / rtcOccluded{4,8,16}
   (the LLVM variants, by the machine's vector width). */
SINGLE(_ZN7mitsuba13rtcIntersect1EPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_9RTCRayHitE,
       n_intersect)
SINGLE(_ZN7mitsuba12rtcOccluded1EPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_6RTCRayE,
       n_occluded)
PACKET(_ZN7mitsuba13rtcIntersect4EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_10RTCRayHit4E,
       4, n_intersect, 0)
PACKET(_ZN7mitsuba13rtcIntersect8EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_10RTCRayHit8E,
       8, n_intersect, 0)
PACKET(_ZN7mitsuba14rtcIntersect16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_11RTCRayHit16E,
       16, n_intersect, 1)
PACKET(_ZN7mitsuba12rtcOccluded4EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_7RTCRay4E,
       4, n_occluded, 0)
PACKET(_ZN7mitsuba12rtcOccluded8EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_7RTCRay8E,
       8, n_occluded, 0)
PACKET(_ZN7mitsuba13rtcOccluded16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_8RTCRay16E,
       16, n_occluded, 0)

__attribute__((destructor)) static void report(void) {
    if (n_intersect + n_occluded == 0)
        return; /* a helper process (the mesh export, a shell): nothing traced */
    const char *out = getenv("RAYCOUNT_OUT");
    FILE *f = out ? fopen(out, "a") : NULL;
    if (!f)
        f = stderr;
    fprintf(f, "intersect %llu occluded %llu packet_calls %llu lanes_in_dump %zu\n", n_intersect,
            n_occluded, n_calls, dump_len);
    if (f != stderr)
        fclose(f);
    const char *file = getenv("DUMP_FILE");
    if (dump_buf && file) {
        FILE *d = fopen(file, "wb");
        if (d) {
            fwrite(dump_buf, sizeof(float), 6 * dump_len, d);
            fclose(d);
        }
    }
}
