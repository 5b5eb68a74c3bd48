//! A plan's jobs as a Kubernetes manifest, DIR/k8s.yaml: one `batch/v1` Job per plan job,
//! each running `terawalk build-job DIR ID` in a container image, with the plan directory on a
//! shared PersistentVolumeClaim mounted at the same absolute path (the plan's paths are
//! absolute). Kubernetes Jobs have no dependencies between them, so each job whose plan job
//! runs "after" others gets an init container that waits for their DIR/done/ID markers (the
//! markers `build-job` leaves when a job succeeds). Nothing here talks to a cluster:
//! `kubectl apply -f DIR/k8s.yaml` starts the build.
//!
//! The text is written by hand rather than by a YAML library: every scalar is a JSON string or
//! number, which YAML reads as the same value, and the structure is fixed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::{Plan, PlanJob};

/// The image when `TERAWALK_IMAGE` is unset: a name to replace, not a published image.
const PLACEHOLDER_IMAGE: &str = "terawalk:latest";
/// The claim when `TERAWALK_PVC` is unset.
const DEFAULT_PVC: &str = "terawalk-plan";
/// The image of the init containers that wait for dependencies.
const WAIT_IMAGE: &str = "busybox:1.36";

/// Where the manifest's jobs run: the image, the claim and where it is mounted.
#[derive(Debug, Clone)]
struct Settings {
    image: String,
    pvc: String,
    /// The claim's mount path: the plan directory, or an ancestor of it (`TERAWALK_PVC_MOUNT`)
    /// that also holds the inputs and the output.
    mount: PathBuf,
}

impl Settings {
    fn from_env(plan: &Plan) -> Result<Settings> {
        let var = |name: &str| std::env::var(name).ok().filter(|v| !v.trim().is_empty());
        let mount = var("TERAWALK_PVC_MOUNT").map_or_else(|| plan.dir.clone(), PathBuf::from);
        if !mount.is_absolute() || !plan.dir.starts_with(&mount) {
            bail!(
                "TERAWALK_PVC_MOUNT={}: the volume's mount path must be the plan directory {} or a directory above it",
                mount.display(),
                plan.dir.display()
            );
        }
        Ok(Settings {
            image: var("TERAWALK_IMAGE").unwrap_or_else(|| PLACEHOLDER_IMAGE.to_owned()),
            pvc: var("TERAWALK_PVC").unwrap_or_else(|| DEFAULT_PVC.to_owned()),
            mount,
        })
    }
}

/// Writes DIR/k8s.yaml (see the module) and says how to start it.
pub fn write_manifest(plan: &Plan, quiet: bool) -> Result<()> {
    let settings = Settings::from_env(plan)?;
    let path = plan.dir.join("k8s.yaml");
    let tmp = plan.dir.join("k8s.yaml.tmp");
    std::fs::write(&tmp, manifest(plan, &settings))
        .and_then(|()| std::fs::rename(&tmp, &path))
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        outln!("wrote {} ({} Kubernetes Jobs, image {})", path.display(), plan.jobs.len(), settings.image);
        outln!("  start: kubectl apply -f {}", path.display());
        outln!(
            "  the store appears at {} when job {} ends",
            plan.output.display(),
            k8s_name(plan, &plan.final_job().id)
        );
        if !plan.output.starts_with(&settings.mount) {
            outln!(
                "  note: the output is outside the volume's mount path {}: set TERAWALK_PVC_MOUNT to a directory \
                 above both, or the store stays inside the pods",
                settings.mount.display()
            );
        }
    }
    Ok(())
}

/// The whole manifest: a header that says what to set, then one document per job.
fn manifest(plan: &Plan, settings: &Settings) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# Written by `terawalk build --plan {} --submit k8s`: the build as Kubernetes Jobs.",
        plan.dir.display()
    );
    let _ = writeln!(
        out,
        "# Start with `kubectl apply -f k8s.yaml`; the store appears at {}.",
        plan.output.display()
    );
    if settings.image == PLACEHOLDER_IMAGE {
        let _ = writeln!(
            out,
            "# The image {PLACEHOLDER_IMAGE} is a placeholder: set TERAWALK_IMAGE to an image with `terawalk` on its PATH."
        );
    }
    let _ = writeln!(
        out,
        "# The PersistentVolumeClaim {} (ReadWriteMany, TERAWALK_PVC) is mounted at {} in every pod; the plan's\n\
         # inputs and output must be on it. A job whose dependency fails waits forever: delete the jobs with\n\
         # `kubectl delete -f k8s.yaml`, fix, and apply again (finished jobs are skipped by their done markers).",
        settings.pvc,
        settings.mount.display()
    );
    for job in &plan.jobs {
        out.push_str("---\n");
        out.push_str(&job_yaml(plan, job, settings));
    }
    out
}

/// One `batch/v1` Job.
fn job_yaml(plan: &Plan, job: &PlanJob, settings: &Settings) -> String {
    let name = k8s_name(plan, &job.id);
    let dir = plan.dir.to_string_lossy();
    let command = [q("terawalk"), q("build-job"), q(&dir), q(&job.id)].join(", ");
    let mut y = String::new();
    let _ = write!(
        y,
        "apiVersion: batch/v1\nkind: Job\nmetadata:\n  name: {}\n  labels:\n{}spec:\n  backoffLimit: 2\n  \
         template:\n    metadata:\n      labels:\n{}    spec:\n      restartPolicy: Never\n",
        q(&name),
        labels(4, &job.id),
        labels(8, &job.id),
    );
    if !job.after.is_empty() {
        let wait = wait_command(&plan.dir, &job.after);
        let _ = write!(
            y,
            "      initContainers:\n        - name: wait-for-dependencies\n          image: {}\n          \
             command: [\"sh\", \"-c\", {}]\n{}",
            q(WAIT_IMAGE),
            q(&wait),
            volume_mounts(settings)
        );
    }
    let memory = job.memory_bytes.to_string();
    let resources = format!("{{memory: {}, cpu: {}}}", q(&memory), q(&job.cpus.to_string()));
    let _ = write!(
        y,
        "      containers:\n        - name: build-job\n          image: {}\n          command: [{command}]\n          \
         workingDir: {}\n          resources:\n            requests: {resources}\n            limits: {resources}\n{}      \
         volumes:\n        - name: plan\n          persistentVolumeClaim:\n            claimName: {}\n",
        q(&settings.image),
        q(&dir),
        volume_mounts(settings),
        q(&settings.pvc),
    );
    y
}

/// The labels of a Job and its pods, indented by `indent` spaces.
fn labels(indent: usize, id: &str) -> String {
    let pad = " ".repeat(indent);
    format!("{pad}app.kubernetes.io/name: terawalk\n{pad}terawalk/job: {}\n", q(id))
}

fn volume_mounts(settings: &Settings) -> String {
    format!(
        "          volumeMounts:\n            - name: plan\n              mountPath: {}\n",
        q(&settings.mount.to_string_lossy())
    )
}

/// The init container's loop: until every dependency's done marker exists, sleep.
fn wait_command(dir: &Path, after: &[String]) -> String {
    let tests: Vec<String> = after
        .iter()
        .map(|id| format!("[ -e '{}' ]", dir.join("done").join(id).to_string_lossy().replace('\'', r"'\''")))
        .collect();
    format!("until {}; do sleep 5; done", tests.join(" && "))
}

/// A Job name: `terawalk-<output's stem>-<id>`, as a DNS label (lower case, digits and '-',
/// at most 63 characters), so that two plans' jobs in one namespace do not collide. The id
/// (at most 40 characters, `read_plan`) is kept whole; the stem gets what is left.
fn k8s_name(plan: &Plan, id: &str) -> String {
    let label = |s: &str, max: usize| -> String {
        let s: String =
            s.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect();
        s.trim_matches('-').chars().take(max).collect::<String>().trim_end_matches('-').to_owned()
    };
    let id = label(id, 40);
    let stem =
        plan.output.file_stem().map(|s| label(&s.to_string_lossy(), 63 - "terawalk--".len() - id.len()));
    match stem.filter(|s| !s.is_empty()) {
        Some(stem) => format!("terawalk-{stem}-{id}"),
        None => format!("terawalk-{id}"),
    }
}

/// A YAML scalar: the JSON string, which YAML reads as the same text.
fn q(s: &str) -> String {
    serde_json::to_string(s).expect("a string is JSON")
}

#[cfg(test)]
mod tests {
    use super::super::tests::example;
    use super::*;

    fn settings() -> Settings {
        Settings {
            image: PLACEHOLDER_IMAGE.into(),
            pvc: "terawalk-plan".into(),
            mount: "/shared/plan".into(),
        }
    }

    #[test]
    fn one_job_per_plan_job_waiting_for_its_dependencies() {
        let plan = example();
        let text = manifest(&plan, &settings());
        assert_eq!(text.matches("\n---\n").count(), 5);
        assert_eq!(text.matches("kind: Job\n").count(), 5);
        assert!(text.contains("is a placeholder: set TERAWALK_IMAGE"));
        assert!(text.contains("name: \"terawalk-scene-cells-001\""));
        assert!(text.contains(r#"command: ["terawalk", "build-job", "/shared/plan", "merge-1-000"]"#));
        assert!(text.contains(
            r#"command: ["sh", "-c", "until [ -e '/shared/plan/done/cells-000' ] && [ -e '/shared/plan/done/cells-001' ]; do sleep 5; done"]"#
        ));
        assert!(text.contains(r#"requests: {memory: "1073741824", cpu: "2"}"#));
        assert!(text.contains("claimName: \"terawalk-plan\""));
        // prepare waits for nothing: four init containers for five jobs.
        assert_eq!(text.matches("initContainers:").count(), 4);
        assert!(text.lines().all(|l| !l.contains('\t')), "YAML has no tabs");
    }

    #[test]
    fn names_are_dns_labels() {
        let mut plan = example();
        plan.output = "/x/My Scene_2024.FINAL.tw".into();
        assert_eq!(k8s_name(&plan, "cells-000"), "terawalk-my-scene-2024-final-cells-000");
        plan.output = "/x/___.tw".into();
        assert_eq!(k8s_name(&plan, "pack"), "terawalk-pack");
        plan.output = format!("/x/{}.tw", "a".repeat(100)).into();
        let long = k8s_name(&plan, &"b".repeat(40));
        assert_eq!(long.len(), 63);
        assert!(long.ends_with(&format!("a-{}", "b".repeat(40))), "{long}");
    }

    /// The same manifest read back by a YAML parser (PyYAML), when python3 has it; the
    /// structural test above runs everywhere.
    #[test]
    fn the_manifest_parses_as_yaml() {
        let has_yaml = std::process::Command::new("python3")
            .args(["-c", "import yaml"])
            .output()
            .is_ok_and(|o| o.status.success());
        if !has_yaml {
            eprintln!("skipped: python3 with PyYAML (python3-yaml) is not installed");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("k8s.yaml");
        std::fs::write(&file, manifest(&example(), &settings())).unwrap();
        let check = r#"
import json, sys, yaml
docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d is not None]
out = []
for d in docs:
    spec = d["spec"]["template"]["spec"]
    c = spec["containers"][0]
    waits = [i["command"][2] for i in spec.get("initContainers", [])]
    out.append([d["apiVersion"], d["kind"], d["metadata"]["name"], d["metadata"]["labels"]["terawalk/job"],
                c["command"], c["resources"]["limits"], spec["volumes"][0]["persistentVolumeClaim"]["claimName"],
                c["volumeMounts"][0]["mountPath"], waits])
print(json.dumps(out))
"#;
        let out = std::process::Command::new("python3").args(["-c", check]).arg(&file).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let docs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(docs.as_array().unwrap().len(), 5);
        let pack = &docs[4];
        assert_eq!(pack[0], "batch/v1");
        assert_eq!(pack[1], "Job");
        assert_eq!(pack[2], "terawalk-scene-pack");
        assert_eq!(pack[3], "pack");
        assert_eq!(pack[4], serde_json::json!(["terawalk", "build-job", "/shared/plan", "pack"]));
        assert_eq!(pack[5], serde_json::json!({"memory": "1073741824", "cpu": "1"}));
        assert_eq!(pack[6], "terawalk-plan");
        assert_eq!(pack[7], "/shared/plan");
        assert!(pack[8][0].as_str().unwrap().contains("[ -e '/shared/plan/done/merge-1-000' ]"));
        assert_eq!(docs[0][8], serde_json::json!([]));
    }
}
