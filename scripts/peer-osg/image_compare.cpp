// image_compare: checks that two renderers drew the same view (same camera, same field of
// view), and puts the two images side by side for a human. Part of scripts/peer-osg.sh; not
// part of terawalk.
//
// Two renderers shade differently (terawalk's flat materials against OSG's headlight), so the
// images are compared by their edges, which only depend on where the geometry lands on screen:
// both are reduced to luminance at about 320 pixels wide, a Sobel gradient magnitude is taken
// and blurred by one pixel, and the normalised cross-correlation (NCC) of the two edge maps is
// searched over shifts of up to ±8 reduced pixels and over scales 0.90..1.10 about the image
// centre. The same camera peaks at shift 0 and scale 1; a different eye or direction moves the
// peak away from shift 0, and a different field of view moves it away from scale 1 (a 6 %
// scale is a 60° against 57° vertical field of view).
//
// usage: image_compare A.png B.png SIDE_BY_SIDE.png   prints one JSON object on stdout
//        image_compare --self-test                    checks the verdicts on synthetic images

#include <osg/Image>
#include <osgDB/ReadFile>
#include <osgDB/WriteFile>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>
#include <vector>

namespace {

/// A single-channel float image, row 0 at the top.
struct Gray {
    int w = 0, h = 0;
    std::vector<float> px;
    float at(int x, int y) const { return px[static_cast<size_t>(y) * w + x]; }
    float& at(int x, int y) { return px[static_cast<size_t>(y) * w + x]; }
};

/// Largest shift searched, in reduced pixels.
const int kMaxShift = 8;
/// Width the images are reduced to before the edge maps are taken.
const int kReducedWidth = 320;
/// Verdict thresholds: the peak must be within this many reduced pixels of shift 0 and this
/// far from scale 1, and the edge maps must correlate at least this much at the identity.
const int kShiftTolerance = 1;
const double kScaleTolerance = 0.015;
const double kMinNcc = 0.2;

/// Luminance of an OSG image (any pixel format OSG can read), row 0 at the top.
Gray luminance(const osg::Image& img) {
    Gray g;
    g.w = img.s();
    g.h = img.t();
    g.px.resize(static_cast<size_t>(g.w) * g.h);
    const bool flip = img.getOrigin() == osg::Image::BOTTOM_LEFT;
    for (int y = 0; y < g.h; ++y)
        for (int x = 0; x < g.w; ++x) {
            osg::Vec4 c = img.getColor(x, flip ? g.h - 1 - y : y);
            g.at(x, y) = 0.299f * c.r() + 0.587f * c.g() + 0.114f * c.b();
        }
    return g;
}

/// Box-filters the image down by an integer factor.
Gray reduce(const Gray& g, int f) {
    Gray r;
    r.w = g.w / f;
    r.h = g.h / f;
    r.px.assign(static_cast<size_t>(r.w) * r.h, 0.0f);
    for (int y = 0; y < r.h; ++y)
        for (int x = 0; x < r.w; ++x) {
            float s = 0;
            for (int j = 0; j < f; ++j)
                for (int i = 0; i < f; ++i) s += g.at(x * f + i, y * f + j);
            r.at(x, y) = s / (f * f);
        }
    return r;
}

/// Sobel gradient magnitude, blurred with a 3×3 box so that nearby edges still overlap.
Gray edges(const Gray& g) {
    Gray e;
    e.w = g.w;
    e.h = g.h;
    e.px.assign(g.px.size(), 0.0f);
    for (int y = 1; y + 1 < g.h; ++y)
        for (int x = 1; x + 1 < g.w; ++x) {
            float gx = g.at(x + 1, y - 1) + 2 * g.at(x + 1, y) + g.at(x + 1, y + 1) - g.at(x - 1, y - 1) -
                       2 * g.at(x - 1, y) - g.at(x - 1, y + 1);
            float gy = g.at(x - 1, y + 1) + 2 * g.at(x, y + 1) + g.at(x + 1, y + 1) - g.at(x - 1, y - 1) -
                       2 * g.at(x, y - 1) - g.at(x + 1, y - 1);
            e.at(x, y) = std::sqrt(gx * gx + gy * gy);
        }
    Gray b = e;
    for (int y = 1; y + 1 < e.h; ++y)
        for (int x = 1; x + 1 < e.w; ++x) {
            float s = 0;
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i) s += e.at(x + i, y + j);
            b.at(x, y) = s / 9;
        }
    return b;
}

/// Edge map of an image at about kReducedWidth pixels wide; also returns the reduction factor.
Gray edge_map(const Gray& g, int& factor) {
    factor = std::max(1, g.w / kReducedWidth);
    return edges(reduce(g, factor));
}

/// NCC of a(p) against b(c + scale·(p − c) + shift) over the pixels of `a` (away from the
/// border) whose sample falls inside `b` (nearest neighbour).
double ncc(const Gray& a, const Gray& b, int dx, int dy, double scale) {
    const double cx = 0.5 * a.w, cy = 0.5 * a.h;
    double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    long n = 0;
    for (int y = kMaxShift; y < a.h - kMaxShift; ++y)
        for (int x = kMaxShift; x < a.w - kMaxShift; ++x) {
            int bx = static_cast<int>(std::lround(cx + scale * (x + 0.5 - cx) - 0.5)) + dx;
            int by = static_cast<int>(std::lround(cy + scale * (y + 0.5 - cy) - 0.5)) + dy;
            if (bx < 0 || by < 0 || bx >= b.w || by >= b.h) continue;
            double va = a.at(x, y), vb = b.at(bx, by);
            sa += va, sb += vb, saa += va * va, sbb += vb * vb, sab += va * vb;
            ++n;
        }
    if (n < 16) return 0.0;
    double cov = sab - sa * sb / n, va = saa - sa * sa / n, vb = sbb - sb * sb / n;
    return va > 0 && vb > 0 ? cov / std::sqrt(va * vb) : 0.0;
}

struct Verdict {
    double ncc = 0;           // at the identity
    int shift_x = 0, shift_y = 0;  // best shift, reduced pixels
    double shift_ncc = 0;
    double scale = 1.0;       // best scale at shift 0
    double scale_ncc = 0;
    int factor = 1;           // reduction factor (full pixels per reduced pixel)
    bool match = false;
};

/// Searches shift and scale for the peak of the edge correlation and judges the views.
Verdict compare(const Gray& a, const Gray& b) {
    Verdict v;
    int fb = 1;
    Gray ea = edge_map(a, v.factor), eb = edge_map(b, fb);
    v.ncc = ncc(ea, eb, 0, 0, 1.0);
    v.shift_ncc = -2;
    for (int dy = -kMaxShift; dy <= kMaxShift; ++dy)
        for (int dx = -kMaxShift; dx <= kMaxShift; ++dx) {
            double c = ncc(ea, eb, dx, dy, 1.0);
            if (c > v.shift_ncc) v.shift_ncc = c, v.shift_x = dx, v.shift_y = dy;
        }
    v.scale_ncc = -2;
    for (int i = -20; i <= 20; ++i) {
        double s = 1.0 + 0.005 * i;
        double c = ncc(ea, eb, 0, 0, s);
        if (c > v.scale_ncc) v.scale_ncc = c, v.scale = s;
    }
    v.match = std::abs(v.shift_x) <= kShiftTolerance && std::abs(v.shift_y) <= kShiftTolerance &&
              std::abs(v.scale - 1.0) <= kScaleTolerance && v.ncc >= kMinNcc;
    return v;
}

/// Writes `a` and `b` next to each other (a left, b right, 8 black pixels between).
bool write_side_by_side(const osg::Image& a, const osg::Image& b, const std::string& out) {
    const int gap = 8, w = a.s() + gap + b.s(), h = std::max(a.t(), b.t());
    osg::ref_ptr<osg::Image> img = new osg::Image;
    img->allocateImage(w, h, 1, GL_RGB, GL_UNSIGNED_BYTE);
    std::fill(img->data(), img->data() + img->getTotalSizeInBytes(), 0);
    auto put = [&](const osg::Image& src, int x0) {
        // Both in OSG's row order; align the tops when the heights differ.
        for (int y = 0; y < src.t(); ++y)
            for (int x = 0; x < src.s(); ++x) {
                osg::Vec4 c = src.getColor(x, y);
                unsigned char* p = img->data(x0 + x, y + (h - src.t()));
                for (int k = 0; k < 3; ++k) p[k] = static_cast<unsigned char>(std::lround(255 * std::min(1.0f, std::max(0.0f, c[k]))));
            }
    };
    put(a, 0);
    put(b, a.s() + gap);
    img->setOrigin(a.getOrigin());
    return osgDB::writeImageFile(*img, out);
}

void print_json(const Verdict& v) {
    std::printf(
        "{\"match\": %s, \"edge_ncc\": %.4f, \"best_shift_px\": [%d, %d], \"best_shift_ncc\": %.4f, "
        "\"best_scale\": %.3f, \"best_scale_ncc\": %.4f}\n",
        v.match ? "true" : "false", v.ncc, v.shift_x * v.factor, v.shift_y * v.factor, v.shift_ncc, v.scale,
        v.scale_ncc);
}

/// A synthetic scene: random filled rectangles of random grey on a grey ground, seen through a
/// camera that is `scale` times zoomed about the centre and moved by (dx, dy) full pixels.
Gray synthetic(unsigned seed, double scale, double dx, double dy) {
    Gray g;
    g.w = 1280;
    g.h = 720;
    g.px.assign(static_cast<size_t>(g.w) * g.h, 0.5f);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    struct Rect { double x0, y0, x1, y1; float v; };
    std::vector<Rect> rects;
    for (int i = 0; i < 60; ++i) {
        double x = u(rng) * 1280, y = u(rng) * 720, w = 20 + u(rng) * 200, h = 20 + u(rng) * 200;
        rects.push_back({x, y, x + w, y + h, static_cast<float>(u(rng))});
    }
    for (int y = 0; y < g.h; ++y)
        for (int x = 0; x < g.w; ++x) {
            double sx = 640 + (x + 0.5 - 640) / scale - dx, sy = 360 + (y + 0.5 - 360) / scale - dy;
            for (const Rect& r : rects)
                if (sx >= r.x0 && sx < r.x1 && sy >= r.y0 && sy < r.y1) g.at(x, y) = r.v;
        }
    return g;
}

/// Checks the verdicts: the same view matches (also with different shading), a shifted view,
/// a zoomed view (another field of view) and an unrelated scene do not.
int self_test() {
    Gray a = synthetic(1, 1.0, 0, 0);
    Gray shaded = a;
    for (float& p : shaded.px) p = 0.2f + 0.6f * p * p;  // other shading, same geometry
    struct Case { const char* name; Gray b; bool expect; };
    std::vector<Case> cases = {
        {"identical", a, true},
        {"reshaded", shaded, true},
        {"shifted 20 px", synthetic(1, 1.0, 20, 0), false},
        {"zoomed 6 %", synthetic(1, 1.06, 0, 0), false},
        {"other scene", synthetic(2, 1.0, 0, 0), false},
    };
    int failures = 0;
    for (const Case& c : cases) {
        Verdict v = compare(a, c.b);
        bool ok = v.match == c.expect;
        std::printf("%-14s %s: ", c.name, ok ? "ok  " : "FAIL");
        print_json(v);
        failures += !ok;
    }
    return failures ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc == 2 && std::string(argv[1]) == "--self-test") return self_test();
    if (argc != 4) {
        std::cerr << "usage: image_compare A.png B.png SIDE_BY_SIDE.png | image_compare --self-test\n";
        return 2;
    }
    osg::ref_ptr<osg::Image> a = osgDB::readRefImageFile(argv[1]);
    osg::ref_ptr<osg::Image> b = osgDB::readRefImageFile(argv[2]);
    for (int i = 0; i < 2; ++i) {
        const osg::Image* img = i ? b.get() : a.get();
        if (!img || !img->data()) {
            std::cerr << "image_compare: " << argv[1 + i] << ": cannot read the image\n";
            return 1;
        }
    }
    if (a->s() != b->s() || a->t() != b->t()) {
        std::cerr << "image_compare: " << argv[1] << " is " << a->s() << "x" << a->t() << " but " << argv[2]
                  << " is " << b->s() << "x" << b->t() << ": render both at the same --size\n";
        return 1;
    }
    if (a->s() < 64 || a->t() < 64) {
        std::cerr << "image_compare: " << argv[1] << ": images under 64x64 are too small to compare\n";
        return 1;
    }
    if (!write_side_by_side(*a, *b, argv[3])) {
        std::cerr << "image_compare: " << argv[3] << ": cannot write\n";
        return 1;
    }
    print_json(compare(luminance(*a), luminance(*b)));
    return 0;
}
