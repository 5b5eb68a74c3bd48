//! Command-line arguments.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use tw_frame::shadow::ShadowOptions;

use crate::generate_spec::{parse_generate_spec, GenerateSpec};
use crate::units::{parse_bytes, parse_count, parse_page_budget};

#[derive(Parser, Debug)]
#[command(
    name = "terawalk",
    version,
    about = "Walk through 3D models of billions of triangles, with or without a GPU",
    long_about = "terawalk reads OBJ, PLY, STL and glTF/GLB models (optionally .gz) of any size in \
                  bounded memory, generates procedural power plants for testing, preprocesses \
                  models into an out-of-core store with a cluster-DAG LOD hierarchy, and renders \
                  that store headless with view-dependent LOD on any wgpu adapter (Mesa's CPU \
                  drivers included).",
    after_help = "Examples:\n  terawalk demo\n  terawalk stats dragon.ply.gz engine.glb\n  \
                  terawalk generate plant --triangles 10M -o plant.ply\n  \
                  terawalk build plant.ply -o plant.tw --memory 1G\n  \
                  terawalk info plant.tw --verify\n  \
                  terawalk render plant.tw -o frame.png --error 1\n  \
                  terawalk preview plant.ply -o plant.png --view iso"
)]
pub struct Cli {
    /// More log output (-v info, -vv debug, -vvv trace); TERAWALK_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// Log only errors, and no progress bars; a command's results (summaries, the files it
    /// wrote) are still printed.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Stream model files and print triangles, vertices, objects, bounds and read speed.
    #[command(after_help = "Examples:\n  terawalk stats model.obj\n  \
                            terawalk stats part1.ply part2.stl.gz scene.glb --json")]
    Stats(StatsArgs),
    /// Generate a procedural scene (a power plant, or a CAD assembly in millimetres) into a
    /// model file.
    #[command(after_help = "Examples:\n  terawalk generate plant --triangles 10M -o plant.ply\n  \
                            terawalk generate plant --triangles 1e9 --seed 7 -o big.ply\n  \
                            terawalk generate plant --triangles 200k -o small.glb\n  \
                            terawalk generate assembly --triangles 24M -o asm.ply\n  \
                            terawalk generate assembly --triangles 24M --one-object -o asm-one.ply\n  \
                            terawalk build asm.ply -o asm.tw --units mm")]
    Generate(GenerateArgs),
    /// Render a quick preview image of model files on the CPU (streaming; any size).
    #[command(after_help = "Examples:\n  terawalk preview plant.ply -o plant.png\n  \
                            terawalk preview dragon.ply.gz -o dragon.png --view front --size 800x800\n  \
                            terawalk preview plant.ply -o in.png --camera \"10,5,1.7;40,5,1.7;0,0,1;70\"\n  \
                            terawalk preview plant.ply -o top.png --camera \"50,50,400;50,50,0;0,1,0;ortho:120\"")]
    Preview(PreviewArgs),
    /// Preprocess inputs into a store file for walkthroughs (out of core, bounded memory).
    #[command(after_help = "Examples:\n  terawalk build plant.ply              # writes plant.tw\n  \
                            terawalk build part1.obj part2.glb -o site.tw --memory 1G --threads 2\n  \
                            terawalk build scan.ply.gz -o scan.tw --up y\n  \
                            terawalk build plant.ply -o fine.tw --cluster-triangles 64\n  \
                            terawalk build --generate plant:1G -o plant.tw --memory 2G\n  \
                            terawalk build plant.ply -o plant.tw --plan /shared/plan --submit slurm\n  \
                            terawalk build plant.ply -o plant.tw --jobs local:2")]
    Build(BuildArgs),
    /// Run one job of a build plan (`terawalk build --plan DIR`); idempotent and restartable.
    #[command(after_help = "Examples:\n  terawalk build plant.ply -o plant.tw --plan plan\n  \
                            terawalk build-job plan prepare\n  \
                            terawalk build-job plan cells-000\n  \
                            terawalk build-job plan pack")]
    BuildJob(BuildJobArgs),
    /// Describe a store file; `--verify` checks every checksum and invariant.
    #[command(after_help = "Examples:\n  terawalk info plant.tw\n  terawalk info plant.tw --verify")]
    Info(InfoArgs),
    /// Render a frame, or every frame of a camera path (PNGs, video), of a store or model on the
    /// GPU (headless; LOD cut and frustum culling as a walk would).
    #[command(after_help = "Examples:\n  terawalk render plant.tw -o frame.png\n  \
                            terawalk render engine.glb -o engine.png   # a model: built into the cache once\n  \
                            terawalk render plant.tw --path walk.json --frames-dir frames/\n  \
                            terawalk render plant.tw --path walk.json --video walk.mp4 --size 1920x1080\n  \
                            terawalk render plant.tw -o lod.png --color level --error 4\n  \
                            terawalk render plant.tw -o sun.png --light sun:40,35   # shadows of a sun\n  \
                            terawalk render plant.tw -o mask.png --light point:120,80,6 --color shadow\n  \
                            terawalk render plant.tw -o in.png --camera \"10,5,1.7;40,5,1.7;0,0,1;70\" --size 1920x1080\n  \
                            WGPU_BACKEND=gl terawalk render plant.tw -o frame.png")]
    Render(RenderArgs),
    /// Render a camera path headless and write a report (HTML with plots, JSON with every figure).
    #[command(after_help = "Examples:\n  terawalk bench plant.tw --path path.json --out report/\n  \
                            terawalk bench plant.tw --path walk.json --occlusion hzb --light sun   # shadows on vs off\n  \
                            terawalk bench plant.tw --path path.json --occlusion none,hzb --compare 10 --exact\n  \
                            terawalk bench plant.tw --path walk.json --occlusion hzb --pipeline serial,gigawalk,switch   # parallel stages\n  \
                            terawalk bench plant.tw --path fly.json --compare 10 --samples 1 --reference-samples 16   # LOD vs brute force against a 16-sample truth\n  \
                            terawalk bench plant.tw --path path.json --reference --frames 20\n  \
                            terawalk bench plant.tw --memory 512M --size 1920x1080 --error 2")]
    Bench(BenchArgs),
    /// Open a store or model in an interactive window: fly, walk or orbit; HUD, controls, debug
    /// view.
    #[command(after_help = "Examples:\n  terawalk view plant.tw\n  \
                            terawalk view   # no file: the open dialog (Ctrl+O, or drop a file on the window)\n  \
                            terawalk view scan.ply.gz --up y   # a model: built into the cache once, progress in the window\n  \
                            terawalk view plant.tw --camera \"10,5,1.7;40,5,1.7;0,0,1;70\" --error 2\n  \
                            terawalk view plant.tw --path walk.json --play\n  \
                            xvfb-run -a terawalk view plant.tw --path walk.json --exit-after 30 --screenshot out.png\n  \
                            terawalk view plant.tw --script tour.txt --screenshot end.png\n  \
                            WGPU_BACKEND=gl terawalk view plant.tw --render-scale 0.5\n  \
                            terawalk view plant.tw --renderer rt --flashlight   # CPU ray tracer, supersampled when still\n\n\
                            Keys: WASD move, mouse drag look, wheel speed, 1/2/3 fly/walk/orbit, right click \
                            orbit around a point, F debug view, L freeze LOD, R record, P play, F12 screenshot, \
                            F1 help, Esc quit (first it clears a pick or measurement). Design review: click \
                            picks an object (name, id, triangles, box, point), H hide, I isolate, Shift+H show \
                            all, M measure (two clicks, snaps to vertices, else edges), Shift+M measure to a \
                            plane (a face, then points), Shift+T model tree (search, select, hide, isolate), \
                            4-9 axis views (+X -X +Y -Y +Z -Z), \
                            0 iso, O orthographic, F11 fullscreen, Tab panels; named viewpoints in the Controls \
                            panel (saved to STORE.views.json). G raster / rt (ray traced), T flashlight (rt). \
                            Shadows (--light): J on/off, [ ] turn the sun, Shift+[ ] its elevation, U point \
                            light at the eye. Ctrl+O (or Open…) opens another store or model in the viewer's \
                            file dialog, and a file dropped on the window opens too (a model is built into \
                            the cache in the background, with a progress window).")]
    View(ViewArgs),
    /// The main job: generate a plant (cached), read it back, render views, print a summary.
    #[command(after_help = "Examples:\n  terawalk demo\n  terawalk demo --triangles 20M --dir /tmp/tw")]
    Demo(DemoArgs),
    /// Generate a camera path: an interior walk at eye height and a fly-over, or an approach from
    /// the overview to a close view (for bench and the viewer).
    #[command(after_help = "Examples:\n  terawalk path plant.tw -o path.json\n  \
                            terawalk path plant.tw -o walk.json --part walk --frames 900 --seed 7\n  \
                            terawalk path plant.tw -o tour.json --walk-share 0.8 --speed 2\n  \
                            terawalk path dragon.tw -o orbit.json   # no floors: a fly-around\n  \
                            terawalk path engine.tw -o approach.json --part approach   # overview to close view\n  \
                            terawalk path engine.tw -o zoom.json --part approach --ortho auto   # orthographic, zooming in\n  \
                            terawalk path plant.tw -o plan.json --part fly --ortho 120   # orthographic, 120 units high\n  \
                            terawalk path ship_mm.tw -o p.json --eye-height 1700")]
    Path(PathArgs),
    /// Write a store's scene back out: the LOD cut `render` draws (or the full-detail triangles
    /// in a region) as GLB, or the whole LOD hierarchy as an OGC 3D Tiles 1.1 tileset.
    #[command(after_help = "Examples:\n  terawalk export plant.tw -o cut.glb\n  \
                            terawalk export plant.tw -o near.glb --error 2 --camera \"10,5,1.7;40,5,1.7;0,0,1;70\"\n  \
                            terawalk export plant.tw -o full.glb --error 0\n  \
                            terawalk export plant.tw -o room.glb --region 0,0,0,20,20,5\n  \
                            terawalk export plant.tw --tiles plant-tiles/")]
    Export(ExportArgs),
    /// Serve occlusion culling over TCP: cull each camera a `bench --cull-server` client sends
    /// and answer with the visible set's delta (the occlusion switch's cull server).
    #[command(after_help = "Examples:\n  terawalk cull-server plant.tw --listen 127.0.0.1:7878\n  \
                            terawalk bench plant.tw --cull-server 127.0.0.1:7878")]
    CullServer(CullServerArgs),
    /// Collision detection on the thesis' scenes (CULLIDE, FAR, the exact CPU reference): per
    /// step milliseconds, pairs found and pairs missed against the reference.
    #[command(after_help = "Examples:\n  terawalk collide cylinders --steps 20\n  \
                            terawalk collide breaking --steps 10 --method cullide,far,reference\n  \
                            terawalk collide bunnies --method cullide --resolution 128,512,1400\n  \
                            terawalk collide cloth --steps 5 --scale 0.1 --method far,reference\n  \
                            terawalk collide tori --method far --groups 256,16\n  \
                            terawalk collide breaking --method cullide --queries batched,occlusion\n  \
                            terawalk collide cylinders --within 0.05 --method far,reference")]
    Collide(crate::commands::collide::CollideArgs),
}

#[derive(Args, Debug)]
pub struct CullServerArgs {
    /// A store file written by `terawalk build` (clients must open the same store).
    pub store: PathBuf,
    /// Address to listen on, host:port (port 0: any free port; the address is printed).
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: String,
    /// Page cache budget of each client's culling walkthrough.
    #[arg(long, default_value = "1G", value_parser = parse_page_budget)]
    pub memory: u64,
    /// GPU memory budget of each client's renderer.
    #[arg(long, default_value = "512M", value_parser = parse_bytes)]
    pub gpu_memory: u64,
    /// The occlusion strategy for clients that leave it to the server (`bench --cull-server`
    /// sends its run's own strategy).
    #[arg(long, default_value = "auto", value_parser = parse_occlusion)]
    pub occlusion: OcclusionChoice,
    /// Open a GPU device per client instead of sharing one.
    #[arg(long)]
    pub own_devices: bool,
    /// Longest wait for a client's read or write, in milliseconds.
    #[arg(long, default_value_t = 10_000, value_name = "MS")]
    pub timeout_ms: u64,
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// A store file written by `terawalk build`.
    pub store: PathBuf,
    /// The GLB file to write (glTF 2.0 binary, y-up, one mesh per object, positions in the
    /// input's coordinates and units).
    #[arg(short, long, required_unless_present = "tiles", conflicts_with = "tiles")]
    pub output: Option<PathBuf>,
    /// Write an OGC 3D Tiles 1.1 tileset into this folder instead: tileset.json and
    /// tiles/N.glb, one tile per LOD level of each part of the hierarchy (refine REPLACE).
    #[arg(long)]
    pub tiles: Option<PathBuf>,
    /// Pixel error threshold τ of the LOD cut, as `render --error` (0 = full resolution).
    #[arg(long, default_value_t = 1.0, conflicts_with_all = ["region", "tiles"])]
    pub error: f32,
    /// Camera "eye;target;up;fovy" in input coordinates, as `render --camera` (also
    /// "eye;target;up;ortho:HEIGHT"), or just "eye;target" (up: the store's axis; the default
    /// field of view). Default: `render`'s
    /// overview of the whole scene.
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["region", "tiles"])]
    pub camera: Option<String>,
    /// Viewport WIDTHxHEIGHT the pixel error is measured in, as `render --size`.
    #[arg(long, default_value = "1280x720", value_parser = parse_size, conflicts_with_all = ["region", "tiles"])]
    pub size: (u32, u32),
    /// Export the full-detail triangles whose three vertices lie in this box instead of a
    /// camera's cut: "minx,miny,minz,maxx,maxy,maxz" in input coordinates.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "tiles")]
    pub region: Option<String>,
    /// --tiles: parts of the hierarchy with at most this many full-detail triangles are not
    /// split into smaller tiles, only refined level by level (fewer, larger tiles when higher).
    #[arg(long, default_value = "64k", value_parser = parse_count, requires = "tiles")]
    pub tile_triangles: u64,
    /// Memory budget of the decoded page cache (at least 1M; the root pages are kept beyond
    /// it).
    #[arg(long, default_value = "1G", value_parser = parse_page_budget)]
    pub memory: u64,
    /// Export and exit 0 even when store pages fail their checksum (a camera's cut is then
    /// drawn from coarser levels, or has holes).
    #[arg(long)]
    pub allow_damaged: bool,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// Memory that vertex tables of OBJ/PLY files may use before spilling to disk (`build`: at
    /// most a quarter of `--memory`).
    #[arg(long, default_value = "192M", value_parser = parse_bytes)]
    pub vertex_memory: u64,
    /// Directory for spill files (default: the system's temp dir).
    #[arg(long)]
    pub spill_dir: Option<PathBuf>,
}

impl ImportArgs {
    pub fn options(&self) -> tw_io::format::ImportOptions {
        tw_io::format::ImportOptions {
            vertex_memory: self.vertex_memory.min(usize::MAX as u64) as usize,
            spill_dir: self.spill_dir.clone(),
        }
    }
}

#[derive(Args, Debug)]
pub struct StatsArgs {
    /// Model files (.obj .ply .stl .gltf .glb, each optionally .gz). Several files form one scene.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Print the figures as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub import: ImportArgs,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum SceneKind {
    /// A power plant: buildings with floors, steel frames, tanks, equipment, a piping network.
    Plant,
    /// A CAD assembly in millimetres: cabinets of densely populated circuit boards, tens of
    /// thousands of small closed parts (SMD chips, ICs, connectors, screws, nuts, valves).
    Assembly,
}

#[derive(Args, Debug)]
pub struct GenerateArgs {
    /// What to generate.
    #[arg(value_enum)]
    pub kind: SceneKind,
    /// Triangles to generate (within 1 %): 1000000, 1M, 1e6 or 10^6.
    #[arg(short, long, default_value = "1M", value_parser = parse_count)]
    pub triangles: u64,
    /// Random seed: the same seed gives the same scene.
    #[arg(short, long, default_value_t = 1)]
    pub seed: u64,
    /// Output file; the format follows the extension: .ply .obj .stl .glb (.ply/.obj/.stl may add .gz).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Assembly only: write everything as one object (like a whole-assembly export without
    /// ids) instead of one object per part.
    #[arg(long)]
    pub one_object: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// From above at an angle, the whole model in view.
    Iso,
    /// Straight down.
    Top,
    /// Along the +Y axis, from the front.
    Front,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coloring {
    /// Object colours from the file (materials), grey otherwise.
    Material,
    /// A distinct colour per object.
    Object,
}

#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// Model files, as for `stats`.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Camera preset framing the model's bounds (ignored with --camera).
    #[arg(long, value_enum, default_value = "iso")]
    pub view: View,
    /// Explicit camera "eye;target;up;fovy": "x,y,z;x,y,z;x,y,z;degrees", or
    /// "x,y,z;x,y,z;x,y,z;ortho:HEIGHT" for an orthographic view HEIGHT input units high.
    #[arg(long, allow_hyphen_values = true)]
    pub camera: Option<String>,
    /// How to colour objects.
    #[arg(long, value_enum, default_value = "material")]
    pub color: Coloring,
    /// Up axis of the model, for the presets: x, y or z (default: the format's convention, y
    /// for glTF/GLB, z for PLY, OBJ and STL, as `build`).
    #[arg(long, value_parser = parse_up_axis)]
    pub up: Option<u8>,
    #[command(flatten)]
    pub import: ImportArgs,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderColoring {
    /// Object colours from the store (materials), grey otherwise.
    Material,
    /// A distinct colour per object.
    Object,
    /// A colour per LOD level (green = full resolution).
    Level,
    /// A distinct colour per cluster.
    Cluster,
    /// The shadow mask of --light: white where the light reaches, black where it is blocked,
    /// grey where surfaces face away from it (for comparing renderers' shadows).
    Shadow,
}

impl RenderColoring {
    /// The renderers' colour mode (tw-gpu and tw-rt share it).
    pub fn mode(self) -> tw_core::color::ColorMode {
        use tw_core::color::ColorMode;
        match self {
            RenderColoring::Material => ColorMode::Material,
            RenderColoring::Object => ColorMode::Object,
            RenderColoring::Level => ColorMode::Level,
            RenderColoring::Cluster => ColorMode::Cluster,
            RenderColoring::Shadow => ColorMode::Shadow,
        }
    }
}

/// Which renderer draws the frames.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum RendererChoice {
    /// The rasterizer (wgpu: a GPU, or Mesa's CPU drivers where there is none).
    #[default]
    Raster,
    /// The CPU ray tracer on every core (tw-rt; no GPU needed): the same LOD cut, shaded the
    /// same way, optionally with a flashlight and hard shadows.
    Rt,
}

/// The image flags `render` and `bench` share (same defaults, same meaning): one definition,
/// so that the two commands cannot drift apart. `view` sizes a window, with its own text.
#[derive(Args, Debug, Clone)]
pub struct FrameArgs {
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel: 1, 4 for 4× multisample anti-aliasing (occlusion culling stays
    /// conservative for every sample), or auto: 4 on a real GPU with Vulkan (or Metal, DX12),
    /// 1 on CPU drivers and GL.
    #[arg(long, default_value = "auto", value_parser = parse_samples)]
    pub samples: SamplesChoice,
    /// How LOD switches are drawn: pop (at once) or dither:N, a screen-door cross-fade of
    /// the old and new clusters over N frames (`dither` alone: 8; at most 64; docs/RUNTIME.md
    /// "Transitions"). The rasterizer's serial frames only.
    #[arg(long, default_value = "pop", value_parser = tw_frame::Transition::parse)]
    pub transition: tw_frame::Transition,
}

/// `--color`, the same in `render`, `bench` and `view`.
#[derive(Args, Debug, Clone)]
pub struct ColorArgs {
    /// How to colour triangles.
    #[arg(long, value_enum, default_value = "material")]
    pub color: RenderColoring,
}

impl ColorArgs {
    /// The renderers' colour mode.
    pub fn mode(&self) -> tw_core::color::ColorMode {
        self.color.mode()
    }
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// A store file written by `terawalk build`, or a model file (as `build` takes), built once
    /// into the cache (see --cache-dir).
    pub store: PathBuf,
    /// Output PNG (one frame; with --path, give --frames-dir or --video instead).
    #[arg(short, long, required_unless_present_any = ["frames_dir", "video"], conflicts_with = "path")]
    pub output: Option<PathBuf>,
    /// A camera path (JSON, as `terawalk path` writes and `bench` reads): render every frame of
    /// it, into --frames-dir and/or --video.
    #[arg(long, requires = "sequence")]
    pub path: Option<PathBuf>,
    /// Folder for the frames of --path: DIR/frame-00000.png, DIR/frame-00001.png, …
    #[arg(long, group = "sequence", requires = "path")]
    pub frames_dir: Option<PathBuf>,
    /// Encode the frames of --path into this video (e.g. walk.mp4) with ffmpeg, which must be
    /// on PATH.
    #[arg(long, group = "sequence", requires = "path")]
    pub video: Option<PathBuf>,
    /// Frame rate of --video (default: the one the path was made for).
    #[arg(long, requires = "video")]
    pub fps: Option<f64>,
    /// Render only the first N frames of --path.
    #[arg(long, requires = "path")]
    pub frames: Option<usize>,
    #[command(flatten)]
    pub frame: FrameArgs,
    /// Camera "eye;target;up;fovy" in input coordinates: "x,y,z;x,y,z;x,y,z;degrees", or
    /// "x,y,z;x,y,z;x,y,z;ortho:HEIGHT" for an orthographic view HEIGHT input units high.
    /// Default: the whole scene from an oblique direction.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "path")]
    pub camera: Option<String>,
    /// Pixel error threshold τ of the LOD cut (0 = full resolution).
    #[arg(long, default_value_t = 1.0)]
    pub error: f32,
    #[command(flatten)]
    pub color: ColorArgs,
    /// Memory budget of the decoded page cache (at least 1M; the root pages are kept beyond
    /// it). With --renderer rt a quarter of it goes to the ray tracer's cluster BVHs.
    #[arg(long, default_value = "1G", value_parser = parse_page_budget)]
    pub memory: u64,
    /// Write the image and exit 0 even when store pages fail their checksum (their geometry is
    /// drawn from coarser levels, or missing); without it such a frame fails the command.
    #[arg(long)]
    pub allow_damaged: bool,
    /// Up axis of the default camera (x, y or z) instead of the one the store records, without
    /// a rebuild (--camera gives its own up vector). A model file is built with it.
    #[arg(long, value_parser = parse_up_axis)]
    pub up: Option<u8>,
    /// Which renderer draws: raster (the default) or rt, the CPU ray tracer.
    #[arg(long, value_enum, default_value = "raster")]
    pub renderer: RendererChoice,
    /// With --renderer rt: light the scene by a flashlight above and beside the eye, with hard
    /// shadows (shadow rays), instead of the headlight.
    #[arg(long)]
    pub flashlight: bool,
    #[command(flatten)]
    pub shadows: ShadowArgs,
    #[command(flatten)]
    pub section: SectionArgs,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// How `render` and `view` open a model file given in place of a store: built once into a
/// cache folder, then reused while the file (path, size, modification time) and the options
/// that shape the store stay the same.
#[derive(Args, Debug, Clone)]
#[command(next_help_heading = "Opening a model file")]
pub struct OpenArgs {
    /// Folder of the stores built from model files. Default: $TERAWALK_CACHE, else
    /// $XDG_CACHE_HOME/terawalk, else ~/.cache/terawalk.
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Most disk space the cached stores may take: each time a model is opened, the least
    /// recently used stores beyond it are removed (never the one being opened).
    #[arg(long, default_value = "20G", value_parser = parse_bytes)]
    pub cache_size: u64,
    /// Units of the model's coordinates, recorded in the store (as `build --units`).
    #[arg(long, default_value = "")]
    pub units: String,
    /// Memory budget of the build (as `build --memory`).
    #[arg(long, default_value = "2G", value_parser = parse_bytes)]
    pub build_memory: u64,
}

/// Section planes and a section box (`render`, `view`, `bench`): the part of the scene on a
/// removed side is neither selected nor drawn (tw_runtime::section).
#[derive(Args, Debug, Clone, Default)]
#[command(next_help_heading = "Section")]
pub struct SectionArgs {
    /// A section plane "NX,NY,NZ,D" in input coordinates: keeps the points p with n·p ≥ D
    /// (e.g. "0,0,1,5" keeps z ≥ 5, "0,0,-1,-5" keeps z ≤ 5). Repeat for up to 6 planes.
    #[arg(long = "section", value_name = "NX,NY,NZ,D", allow_hyphen_values = true, value_parser = tw_runtime::SectionPlane::parse)]
    pub planes: Vec<tw_runtime::SectionPlane>,
    /// A section box "X0,Y0,Z0;X1,Y1,Z1" in input coordinates (min and max corners): keeps
    /// its inside.
    #[arg(long, value_name = "X0,Y0,Z0;X1,Y1,Z1", allow_hyphen_values = true, value_parser = tw_runtime::SectionBox::parse)]
    pub section_box: Option<tw_runtime::SectionBox>,
}

impl SectionArgs {
    /// The section in the scene space of the store of `header` (an error for more than 6
    /// planes).
    pub fn section(&self, header: &tw_store::Header) -> anyhow::Result<tw_runtime::Section> {
        Ok(tw_runtime::Section::to_scene(&self.planes, self.section_box, header.grid_origin)?)
    }
}

/// Shadows of one light (`render`, `view`, `bench`): shadow maps drawn from the light-view sets
/// with the eye's LOD, cross-culled (Govindaraju's thesis ch. 4); the ray tracer casts shadow
/// rays instead.
#[derive(Args, Debug, Clone)]
#[command(next_help_heading = "Shadows")]
pub struct ShadowArgs {
    /// Cast shadows from a light: sun (the shading's own sun direction), sun:AZIMUTH,ELEVATION
    /// (degrees; azimuth around the up axis), or point:X,Y,Z (input coordinates).
    #[arg(long, value_name = "LIGHT", value_parser = parse_light)]
    pub light: Option<tw_runtime::InputLight>,
    /// Shadow-map layer size in texels per side (64..=8192).
    #[arg(long, default_value_t = ShadowOptions::default().size, value_name = "TEXELS", requires = "light")]
    pub shadow_map: u32,
    /// Sun cascades along the view depth (1..=4); a point light uses the faces of a cube.
    #[arg(long, default_value_t = ShadowOptions::default().cascades, value_name = "N", requires = "light")]
    pub cascades: u32,
    /// Depth bias of the shadow lookup, in texels of depth slope.
    #[arg(long, default_value_t = ShadowOptions::default().bias_texels, value_name = "TEXELS", requires = "light")]
    pub shadow_bias: f32,
    /// Cross-culling: classify receivers as fully lit, fully shadowed or partly shadowed against
    /// the light's depth, so only the partly shadowed ones look the map up (the image is the
    /// same either way; off for comparing).
    #[arg(long, default_value = "on", value_parser = parse_on_off, value_name = "on|off", requires = "light", action = clap::ArgAction::Set)]
    pub cross_culling: bool,
    /// Level of detail of the eye's and the light's views: eye (the eye's everywhere: fewest
    /// triangles) or finer (the finer of the eye's pixels and the light's texels: sharper
    /// shadows of far objects near the light, more triangles). Govindaraju's thesis §4.2.1. The
    /// rasterizer's policy; the ray tracer's shadow rays meet the eye's cut.
    #[arg(long, default_value = "eye", value_parser = parse_shadow_lod, value_name = "eye|finer", requires = "light")]
    pub shadow_lod: tw_frame::ShadowLod,
}

impl Default for ShadowArgs {
    /// No light (no shadows), the default map settings.
    fn default() -> Self {
        let o = ShadowOptions::default();
        ShadowArgs {
            light: None,
            shadow_map: o.size,
            cascades: o.cascades,
            shadow_bias: o.bias_texels,
            cross_culling: true,
            shadow_lod: tw_frame::ShadowLod::Eye,
        }
    }
}

impl ShadowArgs {
    /// `--light` and the shadow-map flags, unchecked; `None` without --light. They are checked
    /// when turned into settings ([`tw_bench::ShadowRequest::settings`]), once the store is open.
    pub fn request(&self) -> Option<tw_bench::ShadowRequest> {
        Some(tw_bench::ShadowRequest {
            light: self.light?,
            options: ShadowOptions {
                size: self.shadow_map,
                cascades: self.cascades,
                bias_texels: self.shadow_bias,
            },
            cross_culling: self.cross_culling,
            lod: self.shadow_lod,
        })
    }

    /// The frame's shadow settings for `camera` on a store whose up axis is `up_axis`; `None`
    /// without --light. Errors name the flag.
    pub fn settings(
        &self,
        header: &tw_store::Header,
        up_axis: u8,
        camera: &tw_runtime::Camera,
    ) -> anyhow::Result<Option<tw_frame::ShadowSettings>> {
        self.request().map(|r| r.settings(header, up_axis, camera)).transpose()
    }
}

fn parse_shadow_lod(s: &str) -> Result<tw_frame::ShadowLod, String> {
    tw_frame::ShadowLod::parse(s).ok_or_else(|| format!("expected eye or finer, got {s:?}"))
}

fn parse_light(s: &str) -> Result<tw_runtime::InputLight, String> {
    tw_runtime::InputLight::parse(s).map_err(|e| e.to_string())
}

fn parse_ortho_height(s: &str) -> Result<tw_runtime::OrthoHeight, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(tw_runtime::OrthoHeight::Framed);
    }
    match s.trim().parse::<f64>() {
        Ok(h) if h.is_finite() && h > 0.0 => Ok(tw_runtime::OrthoHeight::Fixed(h)),
        _ => Err(format!("expected a view height > 0 (store units) or \"auto\", got {s:?}")),
    }
}

fn parse_on_off(s: &str) -> Result<bool, String> {
    match s.trim() {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("expected on or off, got {s:?}")),
    }
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// A store file written by `terawalk build`, or a model file (as `build` takes), built once
    /// into the cache (see --cache-dir) while the window shows the build's progress. None: the
    /// window opens with the open dialog (Ctrl+O; or drop a file on it).
    pub store: Option<PathBuf>,
    /// Starting camera "eye;target;up;fovy" in input coordinates: "x,y,z;x,y,z;x,y,z;degrees"
    /// (or "…;ortho:HEIGHT": orthographic). Default: the first frame of --path, else the whole
    /// scene from an oblique direction.
    #[arg(long, allow_hyphen_values = true)]
    pub camera: Option<String>,
    /// A camera path (JSON, as `terawalk path` writes and `bench` reads) to play back.
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Play --path at once (also implied by --exit-after).
    #[arg(long)]
    pub play: bool,
    /// Quit after this many frames (scripted runs: one path frame per frame).
    #[arg(long)]
    pub exit_after: Option<u64>,
    /// Drive the session with a script and quit after its last step: one step per line —
    /// `wait N`, `hold KEY N`, `press KEY` (or `press shift+KEY`), `look DX DY`, `scroll LINES`,
    /// `click X Y`, `view +x|-x|+y|-y|+z|-z|iso`, `save-view NAME`, `load-view NAME`,
    /// `resize WxH`, `minimize`, `restore`, `screenshot FILE`, `screenshot-window FILE` (`#`
    /// comments). With --path, the path advances one frame per frame.
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Save the last frame as PNG on exit (with --exit-after or --script).
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// Save the whole window (HUD and panels included) as PNG just before exit (with --exit-after
    /// or --script).
    #[arg(long)]
    pub screenshot_window: Option<PathBuf>,
    /// Record the camera path from the start into this file (saved on R or at exit). Without
    /// it, R records into --output-dir/terawalk-path-TIME.json.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Folder for F12 screenshots and recordings.
    #[arg(long, default_value = ".")]
    pub output_dir: PathBuf,
    /// Window size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Pixel error threshold τ of the LOD cut (0 = full resolution).
    #[arg(long, default_value_t = 1.0)]
    pub error: f32,
    /// Occlusion culling strategy: none, hzb, queries, gpu-hzb, or auto (the fastest
    /// conservative one on the window's device; all of them give the image of none).
    #[arg(long, default_value = "auto", value_parser = parse_occlusion)]
    pub occlusion: OcclusionChoice,
    /// How LOD switches are drawn: pop (at once) or dither:N, a screen-door cross-fade of
    /// the old and new clusters over N frames (`dither` alone: 8; at most 64; docs/RUNTIME.md
    /// "Transitions"). The rasterizer only.
    #[arg(long, default_value = "pop", value_parser = tw_frame::Transition::parse)]
    pub transition: tw_frame::Transition,
    /// Turn view-frustum culling off.
    #[arg(long)]
    pub no_frustum: bool,
    #[command(flatten)]
    pub color: ColorArgs,
    /// Memory budget of the decoded page cache (at least 1M; the
    /// root pages are kept beyond it).
    #[arg(long, default_value = "1G", value_parser = parse_page_budget)]
    pub memory: u64,
    /// Raise the pixel error while the cut's pages would not fit --memory, back down when
    /// there is room (on, the default: the HUD shows the factor); off keeps the asked-for error
    /// whatever it costs (pages reloaded every frame when the cut does not fit).
    #[arg(long, default_value = "on", value_parser = parse_on_off, value_name = "on|off", action = clap::ArgAction::Set)]
    pub fit_memory: bool,
    /// Scene resolution as a fraction of the window (0.25..=1; CPU rasterizers like 0.5).
    #[arg(long, default_value_t = 1.0)]
    pub render_scale: f32,
    /// Camera mode at the start.
    #[arg(long, value_enum, default_value = "fly")]
    pub mode: CameraModeArg,
    /// Start in the third-person debug view: culling from the starting camera, drawn from a
    /// second camera behind it, with its frustum and the boxes of the visible nodes.
    #[arg(long)]
    pub debug_view: bool,
    /// Up axis for the camera and walk mode's gravity (x, y or z), overriding the one the store
    /// records, without a rebuild. A model file is built with it.
    #[arg(long, value_parser = parse_up_axis)]
    pub up: Option<u8>,
    /// Which renderer draws: raster (the default) or rt, the CPU ray tracer, which adds a
    /// sample per pixel each frame while the camera stands still (up to 64; G switches, T
    /// toggles the flashlight).
    #[arg(long, value_enum, default_value = "raster")]
    pub renderer: RendererChoice,
    /// With --renderer rt: start with the flashlight (above and beside the eye, hard shadows)
    /// instead of the headlight.
    #[arg(long)]
    pub flashlight: bool,
    #[command(flatten)]
    pub shadows: ShadowArgs,
    #[command(flatten)]
    pub section: SectionArgs,
    #[command(flatten)]
    pub open: OpenArgs,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraModeArg {
    /// WASD + mouse look.
    Fly,
    /// Eye height above the ground, gravity along the up axis.
    Walk,
    /// Around a point (right click picks one).
    Orbit,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// A store file written by `terawalk build`.
    pub store: PathBuf,
    /// Camera path (JSON, as `terawalk path` writes and the viewer records). Default: a path
    /// generated like `terawalk path` does (walk and fly-over).
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Render only the first N frames of the path (or generate a path of N frames).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Report folder (index.html, report.json); written atomically.
    #[arg(long, default_value = "bench-report")]
    pub out: PathBuf,
    #[command(flatten)]
    pub frame: FrameArgs,
    /// Pixel error threshold τ of the LOD cut.
    #[arg(long, default_value_t = 1.0)]
    pub error: f32,
    /// Memory budget of the decoded page cache (RAM; at least 1M; the root pages are kept
    /// beyond it). With --renderer rt a quarter of it goes to the ray tracer's cluster BVHs.
    #[arg(long, default_value = "1G", value_parser = parse_page_budget)]
    pub memory: u64,
    /// Occlusion culling strategies, comma-separated (none, hzb, queries, gpu-hzb; auto = the
    /// fastest conservative one on this device); one run each, in this order.
    #[arg(long, value_delimiter = ',', default_value = "auto", value_parser = parse_occlusion)]
    pub occlusion: Vec<OcclusionChoice>,
    /// How each strategy's frames run, comma-separated, one run each: serial (one stage after
    /// the other), gigawalk (select, occluders on a second device, HZB culling and drawing as
    /// concurrent stages, GigaWalk §5; none or hzb) or switch (two occlusion contexts taking
    /// turns, the occlusion switch; none, hzb or queries), select-ahead (the next frame's
    /// selection on a thread of its own while this one is culled and drawn; any strategy) or
    /// alternate (two devices each drawing every other frame whole; any strategy). Frame times
    /// of the parallel ones are their throughput; their latency is recorded beside.
    #[arg(long, value_delimiter = ',', default_value = "serial", value_parser = parse_pipeline)]
    pub pipeline: Vec<tw_frame::Pipeline>,
    /// Render at full detail without any culling (the reference) instead.
    #[arg(long, conflicts_with_all = ["compare", "exact"])]
    pub reference: bool,
    /// Also render the reference every K-th frame: PSNR, differing pixels and the speed-up on
    /// the same frames.
    #[arg(long, value_name = "K")]
    pub compare: Option<usize>,
    /// With --compare: also render each compared frame's full-detail reference supersampled
    /// with N samples per pixel (1, 4, 16 or 64: an ordered s × s grid, drawn at s × the size
    /// and box-filtered in linear light), and record against it both the frame's PSNR and the
    /// brute-force full-detail frame's at the run's samples, and their difference (LOD − brute
    /// force, dB). 1, the default, renders no supersampled reference.
    /// Example: --compare 10 --samples 1 --reference-samples 16
    #[arg(long, default_value = "1", value_name = "N", value_parser = parse_reference_samples, requires = "compare")]
    pub reference_samples: u32,
    /// On the compared frames (every 10th without --compare), count the exact visible objects
    /// and triangles from an item buffer at full detail: culling efficiency = drawn ÷ exact.
    #[arg(long)]
    pub exact: bool,
    /// Load every page a frame needs before drawing it (frames may wait for the disk) instead
    /// of streaming: the same cut whatever the timing, for comparing images.
    #[arg(long)]
    pub wait: bool,
    /// Streaming: raise the pixel error while the cut's pages would not fit --memory, back down
    /// when there is room (on, the default: a cut that does not fit would reload pages every
    /// frame); off keeps the asked-for --error whatever it costs. The report plots the factor.
    #[arg(long, default_value = "on", value_parser = parse_on_off, value_name = "on|off", action = clap::ArgAction::Set)]
    pub fit_memory: bool,
    /// queries: count a tested box visible only when more than N of its samples pass (the
    /// occlusion switch's visible-pixel cut-off; approximate above 0, measure with --compare).
    /// Vulkan only: GL's queries are booleans.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub visible_pixels: u32,
    /// hzb: draw the visible clusters whole, without testing their triangles against the
    /// pyramid (as GigaWalk draws whole objects); for comparing against the default.
    #[arg(long)]
    pub whole_clusters: bool,
    /// GPU memory for resident cluster geometry.
    #[arg(long, default_value = "512M", value_parser = parse_bytes)]
    pub gpu_memory: u64,
    /// Frames rendered at the first camera before measuring (fills the caches).
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Frames embedded in the report as pictures.
    #[arg(long, default_value_t = 4)]
    pub images: usize,
    #[command(flatten)]
    pub color: ColorArgs,
    /// Exit 0 even when store pages fail their checksum (the report lists them); without it a
    /// damaged store fails the command after the report is written.
    #[arg(long)]
    pub allow_damaged: bool,
    /// Cull on a `terawalk cull-server` at this address (host:port): each frame draws the
    /// visible set the server sent for the frame before (one frame of latency), or culls
    /// locally when none came in time.
    #[arg(long, value_name = "ADDR", conflicts_with_all = ["reference", "compare", "exact"])]
    pub cull_server: Option<String>,
    /// With --cull-server: longest wait for a frame's visible set before culling locally, ms.
    #[arg(long, default_value_t = 250, value_name = "MS", requires = "cull_server")]
    pub cull_timeout_ms: u64,
    /// Which renderer draws the frames: raster (the default) or rt, the CPU ray tracer (one run
    /// instead of one per --occlusion strategy: rays need no occlusion culling; --compare
    /// measures it against the rasterized full-detail reference).
    #[arg(long, value_enum, default_value = "raster", conflicts_with_all = ["reference", "exact", "cull_server"])]
    pub renderer: RendererChoice,
    /// With --renderer rt: a flashlight above and beside the eye with hard shadows.
    #[arg(long)]
    pub flashlight: bool,
    /// Measure popping: after each frame, draw its camera with the previous frame's cut and with
    /// its own (whole, no occlusion culling) and record the pixels that differ and their PSNR —
    /// the image change the LOD causes on its own. The extra draws sit between the frames
    /// (outside their clocks) but disturb the caches: compare frame times from runs without it.
    #[arg(long, conflicts_with_all = ["reference", "cull_server", "renderer"])]
    pub popping: bool,
    #[command(flatten)]
    pub shadows: ShadowArgs,
    #[command(flatten)]
    pub section: SectionArgs,
}

/// An `--occlusion` value: a strategy, or `auto` (the fastest conservative one on the device
/// the command renders with, [`tw_frame::Occlusion::fastest_for`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OcclusionChoice {
    Auto,
    Is(tw_frame::Occlusion),
}

impl OcclusionChoice {
    pub fn resolve(self, renderer: &tw_gpu::Renderer) -> tw_frame::Occlusion {
        match self {
            OcclusionChoice::Auto => tw_frame::Occlusion::fastest_for(renderer),
            OcclusionChoice::Is(o) => o,
        }
    }
}

fn parse_pipeline(s: &str) -> Result<tw_frame::Pipeline, String> {
    tw_frame::Pipeline::parse(s).ok_or_else(|| {
        let names: Vec<&str> = tw_frame::Pipeline::ALL.iter().map(|p| p.name()).collect();
        format!("unknown pipeline {s:?}; one of {}", names.join(", "))
    })
}

fn parse_occlusion(s: &str) -> Result<OcclusionChoice, String> {
    if s.trim() == "auto" {
        return Ok(OcclusionChoice::Auto);
    }
    tw_frame::Occlusion::parse(s).map(OcclusionChoice::Is).ok_or_else(|| {
        let names: Vec<&str> = tw_frame::Occlusion::ALL.iter().map(|o| o.name()).collect();
        format!("unknown occlusion strategy {s:?}; one of auto, {}", names.join(", "))
    })
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Size of the generated plant.
    #[arg(short, long, default_value = "5M", value_parser = parse_count)]
    pub triangles: u64,
    /// Seed of the generated plant.
    #[arg(short, long, default_value_t = 1)]
    pub seed: u64,
    /// Cache directory for the generated model and the outputs.
    #[arg(long, default_value = ".terawalk-cache")]
    pub dir: PathBuf,
    /// Frames of the walkthrough path (5 s at 30 fps: 60 % walking, then flying).
    #[arg(long, default_value_t = 150)]
    pub frames: usize,
}

/// A `--samples` value: a count, or `auto` ([`tw_gpu::Renderer::default_samples`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplesChoice {
    Auto,
    Is(u32),
}

impl SamplesChoice {
    pub fn resolve(self, renderer: &tw_gpu::Renderer) -> u32 {
        match self {
            SamplesChoice::Auto => renderer.default_samples(),
            SamplesChoice::Is(n) => n,
        }
    }
}

pub fn parse_samples(s: &str) -> Result<SamplesChoice, String> {
    if s.trim() == "auto" {
        return Ok(SamplesChoice::Auto);
    }
    match s.trim().parse::<u32>() {
        Ok(n) if tw_gpu::SUPPORTED_SAMPLES.contains(&n) => Ok(SamplesChoice::Is(n)),
        _ => Err(format!(
            "expected auto or one of {:?} samples per pixel, got {s:?}",
            tw_gpu::SUPPORTED_SAMPLES
        )),
    }
}

/// A `--reference-samples` count: one of [`tw_frame::supersample::REFERENCE_SAMPLES`].
pub fn parse_reference_samples(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(n) if tw_frame::supersample::grid_side(n).is_some() => Ok(n),
        _ => Err(format!(
            "expected one of {:?} reference samples per pixel (an s × s grid: s = 1, 2, 4, 8), got {s:?}",
            tw_frame::supersample::REFERENCE_SAMPLES
        )),
    }
}

fn parse_up_request(s: &str) -> Result<tw_io::up::UpRequest, String> {
    tw_io::up::UpRequest::parse(s)
}

/// `render`/`view --up`: an axis name as `build --up` takes it (not `auto`, which needs the
/// triangles: rebuild with `build --up auto`).
fn parse_up_axis(s: &str) -> Result<u8, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Err("auto is a build option (it needs the triangles): use x, y or z here".into());
    }
    tw_io::up::parse_axis(s)
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("size must be WIDTHxHEIGHT, got {s:?}"))?;
    let w: u32 = w.trim().parse().map_err(|_| format!("bad width in {s:?}"))?;
    let h: u32 = h.trim().parse().map_err(|_| format!("bad height in {s:?}"))?;
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
        return Err(format!("size {w}x{h} out of range (1..=16384 per side)"));
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn samples() {
        assert_eq!(parse_samples("auto"), Ok(SamplesChoice::Auto));
        assert_eq!(parse_samples("1"), Ok(SamplesChoice::Is(1)));
        assert_eq!(parse_samples("4"), Ok(SamplesChoice::Is(4)));
        for bad in ["3", "0", "", "four", "-4"] {
            assert!(parse_samples(bad).unwrap_err().contains("samples per pixel"), "{bad:?}");
        }
    }

    #[test]
    fn reference_samples() {
        for n in [1, 4, 16, 64] {
            assert_eq!(parse_reference_samples(&n.to_string()), Ok(n));
        }
        for bad in ["0", "2", "9", "32", "256", "", "sixteen", "-4"] {
            let e = parse_reference_samples(bad).unwrap_err();
            assert!(e.contains("[1, 4, 16, 64]") && e.contains("s × s"), "{bad:?}: {e}");
        }
    }

    #[test]
    fn sizes() {
        assert_eq!(parse_size("1280x720"), Ok((1280, 720)));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("big").is_err());
    }

    /// `render`/`view --up` take build's axis names; `auto` (which needs the triangles) and
    /// unknown names are usage errors; without it the store's axis stands.
    #[test]
    fn up_overrides_parse_like_build() {
        let up_of = |args: &[&str]| match Cli::try_parse_from(args).map(|c| c.command) {
            Ok(Command::Render(r)) => Ok(r.up),
            Ok(Command::View(v)) => Ok(v.up),
            Ok(other) => panic!("{other:?}"),
            Err(e) => Err(e.to_string()),
        };
        assert_eq!(up_of(&["terawalk", "render", "s.tw", "-o", "a.png", "--up", "y"]), Ok(Some(1)));
        assert_eq!(up_of(&["terawalk", "render", "s.tw", "-o", "a.png", "--up", "X"]), Ok(Some(0)));
        assert_eq!(up_of(&["terawalk", "render", "s.tw", "-o", "a.png"]), Ok(None));
        assert_eq!(up_of(&["terawalk", "view", "s.tw", "--up", "z"]), Ok(Some(2)));
        let e = up_of(&["terawalk", "render", "s.tw", "-o", "a.png", "--up", "auto"]).unwrap_err();
        assert!(e.contains("build option"), "{e}");
        let e = up_of(&["terawalk", "view", "s.tw", "--up", "w"]).unwrap_err();
        assert!(e.contains("expected x, y or z"), "{e}");
        match Cli::try_parse_from(["terawalk", "build", "a.glb", "-o", "a.tw", "--up", "auto"])
            .unwrap()
            .command
        {
            Command::Build(b) => assert_eq!(b.up, Some(tw_io::up::UpRequest::Auto)),
            other => panic!("{other:?}"),
        }
    }
}

#[derive(Args, Debug)]
pub struct BuildArgs {
    /// Model files (.obj .ply .stl .gltf .glb, each optionally .gz); several form one scene.
    #[arg(required_unless_present = "generate")]
    pub inputs: Vec<PathBuf>,
    /// Build a generated scene instead of files, streamed straight into the build (no model
    /// file on disk): `plant:COUNT` or `assembly:COUNT`, optionally `,seed=N` and, for the
    /// assembly, `,one-object` (e.g. plant:1G, assembly:10M,seed=2). Units: m for the plant,
    /// mm for the assembly, unless `--units`. Needs -o.
    #[arg(long, value_name = "SPEC", value_parser = parse_generate_spec, conflicts_with = "inputs")]
    pub generate: Option<GenerateSpec>,
    /// The store file to write (conventionally .tw). Default: the input's name with the
    /// extension .tw, beside it (`scan.ply.gz` → `scan.tw`); several inputs need it.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Memory budget for the whole build (peak resident memory).
    #[arg(long, default_value = "2G", value_parser = parse_bytes)]
    pub memory: u64,
    /// Worker threads (default: all cores; at most 4 per core). The output is the same for any
    /// count.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65_536))]
    pub threads: Option<u32>,
    /// Up axis of the model: x, y, z, or auto (estimated from the triangles: the axis most
    /// floor-like area faces, confirmed by the thinnest extent; the format default when
    /// unsure). Default: the format's convention, y for glTF/GLB, z for PLY, OBJ and STL.
    #[arg(long, value_parser = parse_up_request)]
    pub up: Option<tw_io::up::UpRequest>,
    /// Units of the input coordinates, recorded in the store (e.g. m, mm).
    #[arg(long, default_value = "")]
    pub units: String,
    /// Directory for working files (default: next to the output).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Most bytes the build may write to disk, working files and the store together (default:
    /// no cap). Every write also leaves 256 MiB free on its disk, cap or not.
    #[arg(long, value_parser = parse_bytes)]
    pub temp_space: Option<u64>,
    /// Most triangles per cluster, the unit of LOD selection and occlusion culling: smaller
    /// clusters cull closer to the exact visible set but make more draws and a larger store.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u32).range(4..=128))]
    pub cluster_triangles: u32,
    /// Triangles per page, the unit the runtime loads and keeps (clusters of one LOD level from
    /// neighbouring cells): smaller pages hold less that a frame does not draw (2048 against
    /// 8192: the 10^8 plant's cuts need ~35 % fewer decoded bytes, docs/benchmarks-log.md,
    /// session 33) but make more, smaller reads and a larger page table.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(256..=65_536))]
    pub page_triangles: u32,
    /// Store each cluster's ray-tracing BVH (its shape: ~1.2 bytes a stored triangle), so that
    /// `--renderer rt` refits it as pages load instead of building it (docs/DESIGN.md D8).
    #[arg(long)]
    pub rt_bvh: bool,
    #[command(flatten)]
    pub import: ImportArgs,
    #[command(flatten)]
    pub plan: PlanArgs,
}

/// `build`'s flags for a build as a plan of jobs (docs/BUILD.md, "A plan of jobs").
#[derive(Args, Debug, Clone, Default)]
pub struct PlanArgs {
    /// Write the build as a plan of jobs into DIR (a shared directory on a cluster) instead of
    /// building: `terawalk build-job DIR JOB` runs one job; `--jobs` or `--submit` run them all.
    #[arg(long, value_name = "DIR")]
    pub plan: Option<PathBuf>,
    /// Run the plan on this machine: `local` (one job at a time) or `local:N` (N at once, each
    /// with the whole `--memory`). Without `--plan` the plan lives in a temporary directory.
    #[arg(long, value_name = "local[:N]", value_parser = parse_local_jobs)]
    pub jobs: Option<usize>,
    /// Submit the plan written to `--plan DIR` to a scheduler: `slurm` (sbatch jobs with
    /// dependencies) or `k8s` (writes DIR/k8s.yaml, Kubernetes Jobs).
    #[arg(long, value_enum, requires = "plan")]
    pub submit: Option<SubmitTarget>,
    /// Cell shards: the plan's LOD jobs, each over a range of cells (default: one per ~10^7
    /// input triangles, estimated from the inputs' sizes).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub shards: Option<u32>,
}

/// Where `build --submit` sends a plan.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SubmitTarget {
    /// Slurm: `sbatch` jobs with `afterok` dependencies over the shared plan directory.
    Slurm,
    /// Kubernetes: a manifest of Jobs over a shared volume, written to DIR/k8s.yaml.
    K8s,
}

/// `--jobs local[:N]`: N ≥ 1 workers (1 without `:N`).
fn parse_local_jobs(s: &str) -> Result<usize, String> {
    let rest = s.trim().strip_prefix("local").ok_or_else(|| format!("`{s}`: expected local or local:N"))?;
    match rest.strip_prefix(':') {
        None if rest.is_empty() => Ok(1),
        Some(n) => match n.parse::<usize>() {
            Ok(n) if (1..=256).contains(&n) => Ok(n),
            _ => Err(format!("`{s}`: N must be a number of workers from 1 to 256")),
        },
        None => Err(format!("`{s}`: expected local or local:N")),
    }
}

#[derive(Args, Debug)]
pub struct BuildJobArgs {
    /// The plan directory written by `terawalk build --plan DIR`.
    pub dir: PathBuf,
    /// The job to run (its id in DIR/plan.json, e.g. prepare, cells-003, merge-1-000, pack).
    pub job: String,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A store file written by `terawalk build`.
    pub store: PathBuf,
    /// Check every page checksum and structural invariant; report the first bad page.
    #[arg(long)]
    pub verify: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathPartArg {
    /// Only the walk at eye height.
    Walk,
    /// Only the fly-over.
    Fly,
    /// A walk, then a rise into the fly-over.
    Both,
    /// From `render`'s overview of the whole model to a close oblique view of its top, the
    /// distance shrinking to an eighth (level of detail benchmarks; nothing is voxelized).
    Approach,
}

#[derive(Args, Debug)]
pub struct PathArgs {
    /// A store file written by `terawalk build`.
    pub store: PathBuf,
    /// The camera path to write (JSON, one camera per frame, input coordinates).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frames in all.
    #[arg(long, default_value_t = 600)]
    pub frames: usize,
    /// Frame rate the path is made for (sets the walking step per frame).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Which parts: walk, fly, both, or approach (overview to close view).
    #[arg(long, value_enum, default_value = "both")]
    pub part: PathPartArg,
    /// Share of the frames that walk with `--part both`.
    #[arg(long, default_value_t = 0.6)]
    pub walk_share: f64,
    /// Eye height above the floor, in the store's units (default: 1.7 m in its units).
    #[arg(long)]
    pub eye_height: Option<f64>,
    /// Walking speed, units per second (default: 1.4 m/s in the store's units).
    #[arg(long)]
    pub speed: Option<f64>,
    /// Vertical field of view, degrees (with `--part approach`, 40 makes the first frame exactly
    /// the camera `render` uses without --camera).
    #[arg(long, default_value_t = 60.0)]
    pub fovy: f64,
    /// Orthographic frames (the same eyes and view directions; the viewer, render and bench show
    /// them orthographic): HEIGHT makes every frame HEIGHT store units high; "auto" makes each
    /// as high as the --fovy perspective view at the distance to what it shows — the approach's
    /// target (so the approach still zooms in to an eighth), the model's centre on the walk and
    /// the fly-over (changing smoothly along the path).
    #[arg(long, value_name = "HEIGHT|auto", value_parser = parse_ortho_height)]
    pub ortho: Option<tw_runtime::OrthoHeight>,
    /// Random seed: the same seed gives the same path.
    #[arg(short, long, default_value_t = 1)]
    pub seed: u64,
    /// Voxel size of the walkable-space analysis (default: eye height / 8).
    #[arg(long)]
    pub voxel: Option<f64>,
    /// Most voxels of the analysis (one bit each; larger scenes get coarser voxels or a window).
    #[arg(long, default_value = "256M", value_parser = parse_count)]
    pub max_voxels: u64,
}
