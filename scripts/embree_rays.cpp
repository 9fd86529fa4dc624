// Embree alone on a file of rays: one ray a call against packets of 16 (BENCHMARKS.md,
// "Rays a sample and ray queries against Embree").
//
// `scripts/bench_traversal.py` times Embree through Mitsuba, whose LLVM variants hand it rays in
// packets of 16 consecutive rays. This times Mitsuba's own copy of Embree 3 directly, built as
// Mitsuba builds it (`RTC_BUILD_QUALITY_HIGH`, no scene flags, one thread; with `--robust`,
// `RTC_SCENE_FLAG_ROBUST`, Embree's conservative mode), on the same triangles, four ways:
// * `intersect1`: `rtcIntersect1` ray by ray;
// * `intersect16`: `rtcIntersect16` on runs of 16 consecutive rays of the file;
// * `intersect16_7`: `rtcIntersect16` on runs of 7 rays (9 lanes invalid): Embree 3's hybrid
//   intersector traces a call of at most 7 valid rays one ray at a time, so this is its
//   single-ray traversal without `rtcIntersect1`'s per-call cost;
// * `occluded1`: `rtcOccluded1` ray by ray.
// Set against striae's figures (`trace_rays`), it tells the traversal apart from the calls.
//
//   M=$(python3 -c "import mitsuba, os; print(os.path.dirname(mitsuba.__file__))")
//   g++ -O2 -std=c++17 -I$M/include -o /tmp/embree_rays scripts/embree_rays.cpp $M/libembree3.so -Wl,-rpath,$M
//   target/release/striae render scenes/glass-teapot.toml --export-meshes /tmp/meshes
//   /tmp/embree_rays [--robust] RAYS.f32 /tmp/meshes/*.obj
//
// RAYS.f32: six little-endian f32 a ray (origin, direction), t in (0, inf), as
// `scripts/mitsuba_rays.py --dump` writes them. The OBJ reader takes `v` and `f` lines only
// (what `--export-meshes` writes). Prints, per query, the median of five timed passes after a
// warm-up, and the number of rays that hit.
#include <embree3/rtcore.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

RTC_NAMESPACE_USE

static bool add_obj(RTCDevice dev, RTCScene scene, const char* path) {
    std::ifstream in(path);
    if (!in) return false;
    std::string line;
    std::vector<float> v;
    std::vector<unsigned> f;
    while (std::getline(in, line)) {
        std::istringstream s(line);
        std::string tag;
        s >> tag;
        if (tag == "v") {
            float x, y, z;
            s >> x >> y >> z;
            v.insert(v.end(), {x, y, z});
        } else if (tag == "f") {
            for (int k = 0; k < 3; k++) {
                std::string w;
                s >> w;
                f.push_back(std::stoul(w) - 1);  // "i", "i/t" or "i/t/n": the vertex index
            }
        }
    }
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = (float*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                               12, v.size() / 3);
    memcpy(vb, v.data(), v.size() * 4);
    auto* ib = (unsigned*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                  12, f.size() / 3);
    memcpy(ib, f.data(), f.size() * 4);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    return true;
}

static void set_ray(RTCRay& r, const float* p) {
    r.org_x = p[0], r.org_y = p[1], r.org_z = p[2], r.tnear = 0.0f;
    r.dir_x = p[3], r.dir_y = p[4], r.dir_z = p[5], r.time = 0.0f;
    r.tfar = INFINITY, r.mask = ~0u, r.id = 0, r.flags = 0;
}

int main(int argc, char** argv) {
    const bool robust = argc > 1 && strcmp(argv[1], "--robust") == 0;
    if (robust) {
        argv++;
        argc--;
    }
    if (argc < 3) {
        fprintf(stderr, "usage: embree_rays [--robust] RAYS.f32 MESH.obj...\n");
        return 2;
    }
    std::ifstream rf(argv[1], std::ios::binary | std::ios::ate);
    if (!rf) {
        fprintf(stderr, "%s: cannot read\n", argv[1]);
        return 1;
    }
    std::vector<float> rays(size_t(rf.tellg()) / 4);
    rf.seekg(0);
    rf.read((char*)rays.data(), rays.size() * 4);
    const size_t n = rays.size() / 6;
    RTCDevice dev = rtcNewDevice("threads=1");
    RTCScene scene = rtcNewScene(dev);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    rtcSetSceneFlags(scene, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    for (int i = 2; i < argc; i++)
        if (!add_obj(dev, scene, argv[i])) {
            fprintf(stderr, "%s: cannot read\n", argv[i]);
            return 1;
        }
    rtcCommitScene(scene);
    const char* names[] = {"intersect1", "intersect16", "intersect16_7", "occluded1"};
    for (int query = 0; query < 4; query++) {
        const size_t run = query == 2 ? 7 : 16;  // rays a 16-wide call
        std::vector<double> seconds;
        size_t hits = 0;
        for (int pass = 0; pass < 6; pass++) {
            hits = 0;
            auto start = std::chrono::steady_clock::now();
            RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            if (query == 0) {
                for (size_t i = 0; i < n; i++) {
                    RTCRayHit rh;
                    set_ray(rh.ray, &rays[6 * i]);
                    rh.hit.geomID = rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
                    rtcIntersect1(scene, &ctx, &rh);
                    hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
                }
            } else if (query == 1 || query == 2) {
                for (size_t i = 0; i < n; i += run) {
                    alignas(64) RTCRayHit16 rh;
                    alignas(64) int valid[16];
                    for (int k = 0; k < 16; k++) {
                        const size_t j = std::min(i + k, n - 1);
                        const float* p = &rays[6 * j];
                        valid[k] = size_t(k) < run && i + k < n ? -1 : 0;
                        rh.ray.org_x[k] = p[0], rh.ray.org_y[k] = p[1], rh.ray.org_z[k] = p[2];
                        rh.ray.dir_x[k] = p[3], rh.ray.dir_y[k] = p[4], rh.ray.dir_z[k] = p[5];
                        rh.ray.tnear[k] = 0.0f, rh.ray.time[k] = 0.0f, rh.ray.tfar[k] = INFINITY;
                        rh.ray.mask[k] = ~0u, rh.ray.id[k] = 0, rh.ray.flags[k] = 0;
                        rh.hit.geomID[k] = rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
                    }
                    rtcIntersect16(valid, scene, &ctx, &rh);
                    for (int k = 0; k < 16; k++)
                        hits += valid[k] && rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
                }
            } else {
                for (size_t i = 0; i < n; i++) {
                    RTCRay r;
                    set_ray(r, &rays[6 * i]);
                    rtcOccluded1(scene, &ctx, &r);
                    hits += r.tfar < 0.0f;  // Embree marks an occluded ray with tfar = -inf
                }
            }
            seconds.push_back(
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        std::sort(seconds.begin() + 1, seconds.end());  // pass 0 warms the caches
        const double median = seconds[3];
        printf("query=%s rays=%zu hits=%zu mrays_per_s=%.3f ns_per_ray=%.1f\n", names[query], n,
               hits, n / median / 1e6, median / n * 1e9);
    }
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    return 0;
}
