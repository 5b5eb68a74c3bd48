//! `terawalk cull-server` and `bench --cull-server` end to end: a server on a free loopback
//! port, a bench that culls on it, the same bench culling locally, and a client of another store
//! that is refused and falls back. Needs a GPU adapter (lavapipe will do); skipped without one
//! unless TERAWALK_REQUIRE_GPU=1.

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

use common::{stderr, stdout, terawalk};

/// A server process and the address it listens on.
struct Server {
    child: Child,
    addr: String,
}

impl Server {
    /// Starts `cull-server STORE --listen 127.0.0.1:0` in `dir`; `None` when there is no GPU
    /// (and the test may skip).
    fn start(dir: &Path, store: &str) -> Option<Server> {
        let mut child = Command::new(env!("CARGO_BIN_EXE_terawalk"))
            .args(["cull-server", store, "--listen", "127.0.0.1:0", "--memory", "256M"])
            .current_dir(dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("runs");
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap()).read_line(&mut line).unwrap();
        let Some(rest) = line.strip_prefix("listening on ") else {
            let o = child.wait_with_output().unwrap();
            let err = stderr(&o);
            if err.contains("no GPU adapter") && std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") {
                eprintln!("SKIPPED: {err} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
                return None;
            }
            panic!("the server did not start: {line}{err}");
        };
        let addr = rest.split_whitespace().next().unwrap().to_string();
        Some(Server { child, addr })
    }

    /// Ctrl-C, then its output: it must stop cleanly, saying what it served.
    fn interrupt(self) -> String {
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let o = self.child.wait_with_output().unwrap();
        assert!(o.status.success(), "the server did not stop cleanly on Ctrl-C: {}", stderr(&o));
        stdout(&o)
    }
}

/// The PNG images (base64) a bench report embeds, in order.
fn report_images(dir: &Path, out: &str) -> Vec<String> {
    let html = std::fs::read_to_string(dir.join(out).join("index.html")).unwrap();
    html.split("base64,").skip(1).map(|s| s.split('"').next().unwrap().to_string()).collect()
}

fn build_store(dir: &Path, seed: &str, name: &str) {
    let ply = format!("{name}.ply");
    let o = terawalk(&["generate", "plant", "--triangles", "20k", "--seed", seed, "-o", &ply], dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let o =
        terawalk(&["build", &ply, "-o", &format!("{name}.tw"), "--memory", "256M", "--threads", "2"], dir);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A camera path of `frames` frames all at the first camera of a generated path: the server's
/// set of the frame before is then the set of the frame drawn, so the images must equal a local
/// bench's.
fn still_path(dir: &Path, store: &str, frames: usize) {
    let o = terawalk(&["path", store, "-o", "walk.json", "--frames", "10"], dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(dir.join("walk.json")).unwrap();
    let mut path: serde_json::Value = serde_json::from_str(&text).unwrap();
    let first = path["frames"][0].clone();
    path["frames"] = serde_json::Value::Array(vec![first; frames]);
    std::fs::write(dir.join("still.json"), serde_json::to_string(&path).unwrap()).unwrap();
}

#[test]
fn bench_through_a_cull_server_draws_the_local_image_and_sends_deltas() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    build_store(d, "1", "p");
    still_path(d, "p.tw", 6);
    let Some(server) = Server::start(d, "p.tw") else { return };
    let bench = |out: &str, server: Option<&str>| {
        let mut args = vec![
            "bench",
            "p.tw",
            "--path",
            "still.json",
            "--size",
            "320x180",
            "--occlusion",
            "none",
            "--wait",
            "--warmup",
            "1",
            "--out",
            out,
        ];
        if let Some(addr) = server {
            args.extend(["--cull-server", addr, "--cull-timeout-ms", "20000"]);
        }
        let o = terawalk(&args, d);
        assert!(o.status.success(), "{}", stderr(&o));
        o
    };
    let remote = bench("remote", Some(&server.addr));
    let out = stdout(&remote);
    assert!(out.contains("cull server frames: 6 of 6 (0 culled locally;"), "{out}{}", stderr(&remote));
    // The camera stands still: after the warm-up frame's full set, every delta is empty.
    assert!(out.contains("delta savings: 100.0 %"), "{out}");
    assert!(out.contains("round trip: median"), "{out}");
    let json = std::fs::read_to_string(d.join("remote/report.json")).unwrap();
    assert!(json.contains("bytes per frame") && json.contains(&server.addr), "{json}");
    bench("local", None);
    let (a, b) = (report_images(d, "remote"), report_images(d, "local"));
    assert!(!a.is_empty());
    assert!(a == b, "the images drawn from the server's sets differ from the local ones");

    // A client of another store is refused, says so once, and culls locally.
    build_store(d, "2", "q");
    let o = terawalk(
        &[
            "bench",
            "q.tw",
            "--frames",
            "3",
            "--size",
            "160x90",
            "--warmup",
            "0",
            "--out",
            "other",
            "--cull-server",
        ],
        d,
    );
    assert!(!o.status.success(), "--cull-server without an address parsed");
    let args = [
        "bench",
        "q.tw",
        "--frames",
        "3",
        "--size",
        "160x90",
        "--warmup",
        "0",
        "--out",
        "other",
        "--cull-server",
        &server.addr,
    ];
    let o = terawalk(&args, d);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("refused") && err.contains("this server serves store"), "{err}");
    assert_eq!(err.matches("culling locally").count(), 1, "{err}");
    assert!(stdout(&o).contains("cull server frames: 0 of 3 (3 culled locally;"), "{}", stdout(&o));

    let said = server.interrupt();
    assert!(said.contains("stopped after") && said.contains("1 refused"), "{said}");
}
