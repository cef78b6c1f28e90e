/*
 * Embree 3's build time as its own users measure it: one device, the scene's buffers set once,
 * `rtcCommitScene` alone timed, best of the rounds, in a fresh process. `tracery bench` times
 * Embree's builds the same way (src/bench/embree.rs); scripts/embree-build-time runs both and
 * compares them.
 *
 *   cc -O2 src/bench/embree_build.c -lembree3 -o embree_build
 *   embree_build TRIANGLES [THREADS] [ROUNDS]
 *
 * TRIANGLES is the file `tracery bench --triangles-out` writes: a little-endian u32 count,
 * then nine f32 per triangle (three vertices). Each triangle gets its own three vertices, as
 * the bench gives them to Embree. Defaults: 1 thread, 5 rounds, medium build quality. Prints
 * one line per round and a last line `best MS`.
 */
#include <embree3/rtcore.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static void fail(const char *what, const char *detail) {
    fprintf(stderr, "embree_build: %s%s%s\n", what, detail ? ": " : "", detail ? detail : "");
    exit(2);
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 4) fail("usage: embree_build TRIANGLES [THREADS] [ROUNDS]", NULL);
    int threads = argc > 2 ? atoi(argv[2]) : 1;
    int rounds = argc > 3 ? atoi(argv[3]) : 5;
    if (threads < 1 || rounds < 1) fail("THREADS and ROUNDS must be positive whole numbers", NULL);

    FILE *f = fopen(argv[1], "rb");
    if (!f) fail("cannot open", argv[1]);
    uint32_t n = 0;
    if (fread(&n, 4, 1, f) != 1) fail("no triangle count in", argv[1]);
    /* Three float3 vertices a triangle, and one float more: Embree reads each vertex with a
       16-byte load, so the buffer must be readable 4 bytes past the last one. */
    float *vertices = malloc(((size_t)9 * n + 1) * sizeof(float));
    uint32_t *indices = malloc((size_t)3 * n * sizeof(uint32_t));
    if (!vertices || !indices) fail("out of memory", NULL);
    if (fread(vertices, sizeof(float), (size_t)9 * n, f) != (size_t)9 * n)
        fail("fewer triangles than its count in", argv[1]);
    fclose(f);
    vertices[(size_t)9 * n] = 0.0f;
    for (size_t i = 0; i < (size_t)3 * n; i++) indices[i] = (uint32_t)i;

    char config[64];
    snprintf(config, sizeof config, "threads=%d", threads);
    RTCDevice device = rtcNewDevice(config);
    if (!device) fail("rtcNewDevice failed", NULL);

    double best = 1e300;
    for (int round = 0; round < rounds; round++) {
        RTCScene scene = rtcNewScene(device);
        rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
        RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                   vertices, 0, 3 * sizeof(float), (size_t)3 * n);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices,
                                   0, 3 * sizeof(uint32_t), n);
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(scene, geometry);
        rtcReleaseGeometry(geometry);
        double start = now_ms();
        rtcCommitScene(scene);
        double ms = now_ms() - start;
        if (rtcGetDeviceError(device) != RTC_ERROR_NONE) fail("the scene build failed", NULL);
        rtcReleaseScene(scene);
        printf("round %d %.3f ms\n", round + 1, ms);
        if (ms < best) best = ms;
    }
    printf("best %.3f\n", best);
    rtcReleaseDevice(device);
    free(vertices);
    free(indices);
    return 0;
}
