// Texture lookups through OpenImageIO's texture system: the twin of texture_lookups.rs (the
// same images, the same lookups in the same order, the same JSON line), built and run by
// tools/bench/texture_cache_oiio.py.
//
//     texture_lookups_oiio --dir DIR --pattern coherent --cache-mib 32 --threads 2
//
// The images are written once into DIR as maketx writes .tx files (tiled 64 x 64, MIP-mapped,
// uncompressed TIFF, 8 bits a channel) and reused by later runs; lookups go through
// TextureSystem::texture with texture handles and per-thread data (its fastest entry), with
// periodic wrap. Bilinear lookups at full resolution use MipModeNoMIP and InterpBilinear;
// trilinear ones MipModeTrilinear with the footprint as derivatives.

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/texture.h>

#include <sys/resource.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

using namespace OIIO;

static const size_t BUCKET = 32;
static const size_t UNIT = 1024;

struct SplitMix {
    uint64_t state;
    uint64_t next() {
        state += 0x9E3779B97F4A7C15ull;
        uint64_t z = state;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    float uniform() { return float(next() >> 40) * (1.0f / 16777216.0f); }
};

struct Lookup {
    size_t image;
    float s, t, width;
};

struct Options {
    std::string dir = ".", pattern = "coherent";
    size_t images = 8, size = 2048, threads = 1;
    double cache_mib = 32;
};

static void make_images(const Options& o) {
    for (size_t k = 0; k < o.images; ++k) {
        std::string path = o.dir + "/image" + std::to_string(k) + "_" + std::to_string(o.size) + ".tx";
        if (FILE* f = fopen(path.c_str(), "rb")) {
            fclose(f);
            continue;
        }
        ImageSpec spec(int(o.size), int(o.size), 4, TypeDesc::UINT8);
        ImageBuf buf(spec);
        std::vector<uint8_t> row(o.size * 4);
        for (size_t y = 0; y < o.size; ++y) {
            for (size_t x = 0; x < o.size; ++x) {
                SplitMix h{uint64_t((k * 4096 + y / 16) * 4096 + x / 16)};
                row[x * 4 + 0] = uint8_t((x * 7 + y * 3 + k * 50) & 255);
                row[x * 4 + 1] = uint8_t((x ^ y) & 255);
                row[x * 4 + 2] = uint8_t(h.next() & 255);
                row[x * 4 + 3] = 255;
            }
            buf.set_pixels(ROI(0, int(o.size), int(y), int(y) + 1, 0, 1, 0, 4), TypeDesc::UINT8,
                           row.data());
        }
        ImageSpec config;
        config.tile_width = config.tile_height = 64;
        config.attribute("compression", "none");
        config.attribute("maketx:filtername", "box");
        if (!ImageBufAlgo::make_texture(ImageBufAlgo::MakeTxTexture, buf, path, config)) {
            fprintf(stderr, "make_texture %s: %s\n", path.c_str(), OIIO::geterror().c_str());
            exit(1);
        }
    }
}

int main(int argc, char** argv) {
    Options o;
    for (int i = 1; i + 1 < argc; i += 2) {
        std::string a = argv[i], v = argv[i + 1];
        if (a == "--dir") o.dir = v;
        else if (a == "--pattern") o.pattern = v;
        else if (a == "--images") o.images = std::stoul(v);
        else if (a == "--size") o.size = std::stoul(v);
        else if (a == "--threads") o.threads = std::stoul(v);
        else if (a == "--cache-mib") o.cache_mib = std::stod(v);
        else {
            fprintf(stderr, "unknown argument %s\n", a.c_str());
            return 2;
        }
    }
    make_images(o);
    TextureSystem* ts = TextureSystem::create(false);
    ts->attribute("max_memory_MB", float(o.cache_mib));
    std::vector<TextureSystem::TextureHandle*> handles;
    for (size_t k = 0; k < o.images; ++k) {
        std::string path = o.dir + "/image" + std::to_string(k) + "_" + std::to_string(o.size) + ".tx";
        handles.push_back(ts->get_texture_handle(ustring(path)));
    }
    bool trilinear = o.pattern == "trilinear";
    size_t units, screen = trilinear ? o.size / 4 : o.size, spp = trilinear ? 4 : 1;
    size_t across = (screen + BUCKET - 1) / BUCKET;
    float width = trilinear ? 4.0f / float(o.size) : 0.0f;
    if (o.pattern == "incoherent") units = o.images * o.size * o.size / 4 / UNIT;
    else if (o.pattern == "coherent" || trilinear) units = o.images * across * across;
    else {
        fprintf(stderr, "unknown pattern %s\n", o.pattern.c_str());
        return 2;
    }
    auto unit = [&](size_t u, std::vector<Lookup>& out) {
        SplitMix rng{u};
        if (o.pattern == "incoherent") {
            for (size_t i = 0; i < UNIT; ++i) {
                size_t k = size_t(rng.next() % o.images);
                float s = rng.uniform();
                float t = rng.uniform();
                out.push_back({k, s, t, 0.0f});
            }
            return;
        }
        size_t k = u / (across * across), b = u % (across * across);
        size_t bx = b % across * BUCKET, by = b / across * BUCKET;
        for (size_t py = by; py < std::min(by + BUCKET, screen); ++py)
            for (size_t px = bx; px < std::min(bx + BUCKET, screen); ++px)
                for (size_t i = 0; i < spp; ++i) {
                    float s = (float(px) + rng.uniform()) / float(screen);
                    float t = (float(py) + rng.uniform()) / float(screen);
                    out.push_back({k, s, t, width});
                }
    };
    std::atomic<size_t> next{0};
    std::vector<size_t> counts(o.threads);
    std::vector<double> sums(o.threads);
    auto start = std::chrono::steady_clock::now();
    std::vector<std::thread> workers;
    for (size_t w = 0; w < o.threads; ++w)
        workers.emplace_back([&, w] {
            TextureSystem::Perthread* thread_info = ts->get_perthread_info();
            TextureOpt opt;
            opt.swrap = opt.twrap = TextureOpt::WrapPeriodic;
            opt.interpmode = TextureOpt::InterpBilinear;
            opt.mipmode = trilinear ? TextureOpt::MipModeTrilinear : TextureOpt::MipModeNoMIP;
            std::vector<Lookup> batch;
            batch.reserve(BUCKET * BUCKET * 4);
            size_t n = 0;
            double sum = 0;
            for (;;) {
                size_t u = next.fetch_add(1);
                if (u >= units) break;
                batch.clear();
                unit(u, batch);
                float acc[3] = {0, 0, 0};
                for (const Lookup& l : batch) {
                    float result[4];
                    ts->texture(handles[l.image], thread_info, opt, l.s, l.t, l.width, 0.0f, 0.0f,
                                l.width, 4, result);
                    acc[0] += result[0];
                    acc[1] += result[1];
                    acc[2] += result[2];
                }
                n += batch.size();
                sum += double(acc[0] + acc[1] + acc[2]);
            }
            counts[w] = n;
            sums[w] = sum;
        });
    for (auto& w : workers) w.join();
    double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    size_t lookups = 0;
    double sum = 0;
    for (size_t w = 0; w < o.threads; ++w) {
        lookups += counts[w];
        sum += sums[w];
    }
    int tiles_read = 0;
    long long bytes_read = 0;
    ts->imagecache()->getattribute("stat:tiles_created", tiles_read);
    ts->imagecache()->getattribute("stat:bytes_read", TypeDesc::INT64, &bytes_read);
    struct rusage usage;
    getrusage(RUSAGE_SELF, &usage);
    printf("{\"renderer\": \"oiio\", \"pattern\": \"%s\", \"threads\": %zu, \"cache_mib\": %g, "
           "\"lookups\": %zu, \"seconds\": %.4f, \"lookups_per_second\": %.0f, "
           "\"checksum\": %.6f, \"tiles_read\": %d, \"mib_read\": %.1f, \"peak_mib\": %.1f}\n",
           o.pattern.c_str(), o.threads, o.cache_mib, lookups, seconds, lookups / seconds,
           sum / double(lookups), tiles_read, bytes_read / 1048576.0, usage.ru_maxrss / 1024.0);
    TextureSystem::destroy(ts);
    return 0;
}
