// osg_walk: renders a terawalk camera path with a stock OpenSceneGraph 3.6 viewer and reports
// load time, per-frame time and peak memory. It is the peer side of scripts/peer-osg.sh and
// not part of terawalk (nothing in Cargo builds or links it).
//
// What it does, and why each choice keeps the comparison fair:
// - The model is read with osgDB::readNodeFile (the plugin picks the format: PLY, OBJ, STL, …)
//   and optimised with osgUtil::Optimizer's defaults, as the stock `osgviewer` application does.
// - The camera of every frame comes from the path: eye, target and up are used as they are
//   (terawalk paths are in the input files' coordinates, the same ones OSG loads), and `fovy`
//   is the vertical field of view in degrees with aspect = width / height, the convention of
//   crates/tw-runtime/src/camera.rs. The clip planes are left to OSG's default
//   near/far computation from bounding volumes: like terawalk's, they always enclose the whole
//   scene, so they clip nothing that terawalk shows, and OSG keeps the depth precision its
//   conventional (not reversed) depth buffer needs.
// - There is no camera manipulator: the view matrix set before `viewer.frame()` is the one
//   drawn. A frame's time is `viewer.frame()` (update, cull, draw, swap) plus a glFinish, so
//   the GPU (llvmpipe under xvfb-run) has finished the frame when the clock stops.
// - `--warmup` frames at the first camera run before timing, as `terawalk bench --warmup`
//   does (OSG compiles its display lists on the first frame).
// - Peak memory is the process's VmHWM (peak resident set) from /proc/self/status.
//
// Input: a path as text (scripts/peer-osg/path_to_text.py converts terawalk's JSON): a first
// line "terawalk-path-text 1", then one frame per line: ex ey ez tx ty tz ux uy uz fovy.
// Output: a summary on stdout and, with --json, every figure as JSON.

#include <osg/Camera>
#include <osg/GL>
#include <osg/GraphicsContext>
#include <osg/Image>
#include <osg/Matrixd>
#include <osgDB/ReadFile>
#include <osgDB/WriteFile>
#include <osgUtil/Optimizer>
#include <osgViewer/Viewer>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace {

/// One frame's camera in input coordinates; fovy in degrees (vertical).
struct PathFrame {
    osg::Vec3d eye, target, up;
    double fovy = 60.0;
};

struct Options {
    std::string model;
    std::string path;
    int width = 1280;
    int height = 720;
    long frames = -1;  // all
    int warmup = 3;
    bool optimize = true;
    std::string capture;  // PNG of the first path frame, untimed
    std::string json;
};

const char* const kUsage =
    "usage: osg_walk MODEL PATH.txt [--size WxH] [--frames N] [--warmup N] [--no-optimize]\n"
    "                [--capture FIRST.png] [--json OUT.json]\n"
    "PATH.txt: 'terawalk-path-text 1', then per frame: ex ey ez tx ty tz ux uy uz fovy\n";

/// Parses "WxH" into positive width and height.
bool parse_size(const std::string& s, int& w, int& h) {
    char x = 0;
    std::istringstream in(s);
    if (!(in >> w >> x >> h) || x != 'x' || w <= 0 || h <= 0 || w > 16384 || h > 16384) return false;
    std::string rest;
    return !(in >> rest);
}

/// Parses a non-negative integer argument; false on anything else.
bool parse_count(const std::string& s, long& out) {
    if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos || s.size() > 12) return false;
    out = std::stol(s);
    return true;
}

/// Reads the command line; on error prints the reason and returns false.
bool parse_args(int argc, char** argv, Options& o) {
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&](std::string& out) {
            if (i + 1 >= argc) {
                std::cerr << "osg_walk: " << a << " needs a value\n";
                return false;
            }
            out = argv[++i];
            return true;
        };
        std::string v;
        if (a == "--size") {
            if (!value(v)) return false;
            if (!parse_size(v, o.width, o.height)) {
                std::cerr << "osg_walk: --size " << v << ": expected WIDTHxHEIGHT, e.g. 1280x720\n";
                return false;
            }
        } else if (a == "--frames" || a == "--warmup") {
            if (!value(v)) return false;
            long n = 0;
            if (!parse_count(v, n)) {
                std::cerr << "osg_walk: " << a << " " << v << ": expected a whole number\n";
                return false;
            }
            if (a == "--frames") o.frames = n; else o.warmup = static_cast<int>(std::min(n, 1000L));
        } else if (a == "--no-optimize") {
            o.optimize = false;
        } else if (a == "--capture") {
            if (!value(o.capture)) return false;
        } else if (a == "--json") {
            if (!value(o.json)) return false;
        } else if (a == "-h" || a == "--help") {
            std::cout << kUsage;
            std::exit(0);
        } else if (!a.empty() && a[0] == '-') {
            std::cerr << "osg_walk: unknown option " << a << "\n" << kUsage;
            return false;
        } else {
            positional.push_back(a);
        }
    }
    if (positional.size() != 2) {
        std::cerr << kUsage;
        return false;
    }
    o.model = positional[0];
    o.path = positional[1];
    return true;
}

/// Reads the text path; errors name the file and line.
bool read_path(const std::string& file, std::vector<PathFrame>& frames, std::string& err) {
    std::ifstream in(file);
    if (!in) {
        err = file + ": cannot open";
        return false;
    }
    std::string line;
    long lineno = 0;
    if (!std::getline(in, line) || line != "terawalk-path-text 1") {
        err = file + ":1: expected the header 'terawalk-path-text 1'";
        return false;
    }
    ++lineno;
    while (std::getline(in, line)) {
        ++lineno;
        if (line.empty()) continue;
        std::istringstream ls(line);
        double v[10];
        int n = 0;
        while (n < 10 && (ls >> v[n])) ++n;
        std::string rest;
        bool finite = std::all_of(v, v + n, [](double x) { return std::isfinite(x); });
        if (n != 10 || (ls >> rest) || !finite) {
            err = file + ":" + std::to_string(lineno) + ": expected 10 finite numbers (eye, target, up, fovy)";
            return false;
        }
        PathFrame f;
        f.eye.set(v[0], v[1], v[2]);
        f.target.set(v[3], v[4], v[5]);
        f.up.set(v[6], v[7], v[8]);
        f.fovy = v[9];
        osg::Vec3d dir = f.target - f.eye;
        if (dir.length2() == 0.0 || (dir ^ f.up).length2() <= 1e-12 * dir.length2() * f.up.length2() ||
            !(f.fovy >= 1.0 && f.fovy <= 179.0)) {
            err = file + ":" + std::to_string(lineno) +
                  ": eye = target, up parallel to the view, or fovy outside 1..179 degrees";
            return false;
        }
        frames.push_back(f);
    }
    if (frames.empty()) {
        err = file + ": the path has no frames";
        return false;
    }
    return true;
}

/// Peak resident set size in bytes (VmHWM), 0 if unknown.
long long peak_rss_bytes() {
    std::ifstream in("/proc/self/status");
    std::string key;
    while (in >> key) {
        if (key == "VmHWM:") {
            long long kb = 0;
            in >> kb;
            return kb * 1024;
        }
        std::string rest;
        std::getline(in, rest);
    }
    return 0;
}

/// Reads the back buffer into `image` after the draw of an armed frame (before the swap), and
/// records the renderer string once, while the context is current.
struct CaptureCallback : public osg::Camera::DrawCallback {
    mutable bool armed = false;
    mutable std::string renderer;
    osg::ref_ptr<osg::Image> image = new osg::Image;
    int width, height;
    CaptureCallback(int w, int h) : width(w), height(h) {}
    void operator()(osg::RenderInfo&) const override {
        if (renderer.empty()) {
            const GLubyte* r = glGetString(GL_RENDERER);
            renderer = r ? reinterpret_cast<const char*>(r) : "unknown";
        }
        if (!armed) return;
        armed = false;
        glReadBuffer(GL_BACK);
        image->readPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE);
    }
};

/// Puts the path frame's camera on the viewer: look-at view, perspective with the vertical
/// field of view in degrees (near/far are recomputed by OSG from the scene's bounds).
void set_camera(osgViewer::Viewer& viewer, const PathFrame& f, double aspect) {
    osg::Camera* cam = viewer.getCamera();
    cam->setViewMatrixAsLookAt(f.eye, f.target, f.up);
    cam->setProjectionMatrixAsPerspective(f.fovy, aspect, 0.1, 1000.0);
}

/// Renders one frame and waits for the GPU; returns milliseconds.
double timed_frame(osgViewer::Viewer& viewer, osg::GraphicsContext* gc) {
    auto t0 = std::chrono::steady_clock::now();
    viewer.frame();
    gc->makeCurrent();
    glFinish();
    auto t1 = std::chrono::steady_clock::now();
    return std::chrono::duration<double, std::milli>(t1 - t0).count();
}

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Escapes a string for JSON.
std::string json_str(const std::string& s) {
    std::string o = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') o += '\\', o += c;
        else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
        else o += c;
    }
    return o + "\"";
}

struct Report {
    double read_s = 0, optimize_s = 0;
    std::vector<double> frame_ms;
    long long peak_rss = 0;
    std::string renderer;
};

bool write_json(const Options& o, const Report& r, std::string& err) {
    std::ofstream out(o.json);
    if (!out) {
        err = o.json + ": cannot create";
        return false;
    }
    double med = median(r.frame_ms);
    out << "{\n  \"format\": \"terawalk-peer-osg\",\n  \"version\": 1,\n"
        << "  \"model\": " << json_str(o.model) << ",\n  \"path\": " << json_str(o.path) << ",\n"
        << "  \"size\": [" << o.width << ", " << o.height << "],\n"
        << "  \"renderer\": " << json_str(r.renderer) << ",\n"
        << "  \"osg_version\": " << json_str(osgGetVersion()) << ",\n"
        << "  \"optimize\": " << (o.optimize ? "true" : "false") << ",\n"
        << "  \"read_s\": " << r.read_s << ",\n  \"optimize_s\": " << r.optimize_s << ",\n"
        << "  \"load_s\": " << r.read_s + r.optimize_s << ",\n"
        << "  \"frames\": " << r.frame_ms.size() << ",\n"
        << "  \"median_ms\": " << med << ",\n  \"median_fps\": " << (med > 0 ? 1000.0 / med : 0) << ",\n"
        << "  \"peak_rss_mb\": " << r.peak_rss / 1e6 << ",\n  \"frame_ms\": [";
    for (size_t i = 0; i < r.frame_ms.size(); ++i) out << (i ? ", " : "") << r.frame_ms[i];
    out << "]\n}\n";
    out.close();
    if (!out) {
        err = o.json + ": cannot write";
        return false;
    }
    return true;
}

/// Creates the window (on xvfb-run's screen) and attaches it to the viewer's camera.
osg::ref_ptr<osg::GraphicsContext> make_context(osgViewer::Viewer& viewer, const Options& o) {
    osg::ref_ptr<osg::GraphicsContext::Traits> t = new osg::GraphicsContext::Traits;
    t->readDISPLAY();  // xvfb-run picks a free display number; the traits default to :0
    t->setUndefinedScreenDetailsToDefaultScreen();
    t->x = 0;
    t->y = 0;
    t->width = o.width;
    t->height = o.height;
    t->windowDecoration = false;
    t->doubleBuffer = true;
    t->vsync = false;
    t->sharedContext = nullptr;
    osg::ref_ptr<osg::GraphicsContext> gc = osg::GraphicsContext::createGraphicsContext(t.get());
    if (!gc) return nullptr;
    osg::Camera* cam = viewer.getCamera();
    cam->setGraphicsContext(gc.get());
    cam->setViewport(new osg::Viewport(0, 0, o.width, o.height));
    cam->setDrawBuffer(GL_BACK);
    cam->setReadBuffer(GL_BACK);
    return gc;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    if (!parse_args(argc, argv, o)) return 2;
    std::vector<PathFrame> path;
    std::string err;
    if (!read_path(o.path, path, err)) {
        std::cerr << "osg_walk: " << err << "\n";
        return 1;
    }
    if (o.frames >= 0 && static_cast<size_t>(o.frames) < path.size()) path.resize(std::max(1L, o.frames));

    Report r;
    auto t0 = std::chrono::steady_clock::now();
    osg::ref_ptr<osg::Node> model = osgDB::readRefNodeFile(o.model);
    auto t1 = std::chrono::steady_clock::now();
    if (!model) {
        std::cerr << "osg_walk: " << o.model << ": OpenSceneGraph could not read the model\n";
        return 1;
    }
    if (o.optimize) {
        osgUtil::Optimizer optimizer;
        optimizer.optimize(model.get());
    }
    auto t2 = std::chrono::steady_clock::now();
    r.read_s = std::chrono::duration<double>(t1 - t0).count();
    r.optimize_s = std::chrono::duration<double>(t2 - t1).count();

    osgViewer::Viewer viewer;
    viewer.setThreadingModel(osgViewer::Viewer::SingleThreaded);
    viewer.setKeyEventSetsDone(0);
    osg::ref_ptr<osg::GraphicsContext> gc = make_context(viewer, o);
    if (!gc) {
        std::cerr << "osg_walk: cannot create a " << o.width << "x" << o.height
                  << " OpenGL window (run under xvfb-run, with DISPLAY set)\n";
        return 1;
    }
    osg::ref_ptr<CaptureCallback> capture = new CaptureCallback(o.width, o.height);
    viewer.getCamera()->setFinalDrawCallback(capture.get());
    viewer.setSceneData(model.get());
    viewer.realize();
    if (!viewer.isRealized()) {
        std::cerr << "osg_walk: the viewer could not be realized (no OpenGL context)\n";
        return 1;
    }
    const double aspect = static_cast<double>(o.width) / o.height;

    set_camera(viewer, path[0], aspect);
    for (int i = 0; i < o.warmup; ++i) timed_frame(viewer, gc.get());
    r.frame_ms.reserve(path.size());
    for (const PathFrame& f : path) {
        set_camera(viewer, f, aspect);
        r.frame_ms.push_back(timed_frame(viewer, gc.get()));
    }
    if (!o.capture.empty()) {
        set_camera(viewer, path[0], aspect);
        capture->armed = true;
        timed_frame(viewer, gc.get());
        if (!capture->image->data() || !osgDB::writeImageFile(*capture->image, o.capture)) {
            std::cerr << "osg_walk: " << o.capture << ": cannot write the captured frame\n";
            return 1;
        }
    }
    r.peak_rss = peak_rss_bytes();
    r.renderer = capture->renderer;

    double med = median(r.frame_ms);
    std::printf("osg %s, renderer %s, %dx%d\n", osgGetVersion(), r.renderer.c_str(), o.width, o.height);
    std::printf("load %.2f s (read %.2f s, optimize %.2f s)\n", r.read_s + r.optimize_s, r.read_s, r.optimize_s);
    for (size_t i = 0; i < r.frame_ms.size(); ++i) std::printf("frame %zu: %.2f ms\n", i, r.frame_ms[i]);
    std::printf("%zu frames, median %.2f ms (%.2f fps), peak RSS %.1f MB\n", r.frame_ms.size(), med,
                med > 0 ? 1000.0 / med : 0.0, r.peak_rss / 1e6);
    if (!o.json.empty() && !write_json(o, r, err)) {
        std::cerr << "osg_walk: " << err << "\n";
        return 1;
    }
    return 0;
}
