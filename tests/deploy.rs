//! The Kubernetes manifest in deploy/: an Indexed Job whose pods render one range of the
//! samples each, by JOB_COMPLETION_INDEX, into a shared volume, and a merge job reading them
//! there. There is no cluster here: the manifest is read, checked, and its pods' script run
//! for every index with a stand-in `tracery` that prints its arguments.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use yaml_rust2::{Yaml, YamlLoader};

fn at<'a>(y: &'a Yaml, path: &[&str]) -> &'a Yaml {
    path.iter().fold(y, |y, k| &y[*k])
}

fn text(y: &Yaml) -> &str {
    y.as_str()
        .unwrap_or_else(|| panic!("expected text, got {y:?}"))
}

/// The container's environment as a map.
fn env_of(container: &Yaml) -> BTreeMap<String, String> {
    container["env"]
        .as_vec()
        .map(|v| {
            v.iter()
                .map(|e| (text(&e["name"]).to_string(), text(&e["value"]).to_string()))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn the_kubernetes_indexed_job_renders_every_sample_once_and_merges() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/render-job.yaml");
    let docs = YamlLoader::load_from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let job = |step: &str| {
        docs.iter()
            .find(|d| text(at(d, &["metadata", "labels", "step"])) == step)
            .unwrap_or_else(|| panic!("no document labelled step={step}"))
    };
    let (render, merge) = (job("render"), job("merge"));
    for d in [render, merge] {
        assert_eq!(text(&d["kind"]), "Job");
        assert_eq!(text(&d["apiVersion"]), "batch/v1");
    }

    // The render job: indexed, one pod per task, the index read from JOB_COMPLETION_INDEX.
    let spec = &render["spec"];
    assert_eq!(text(&spec["completionMode"]), "Indexed");
    let completions = spec["completions"].as_i64().unwrap();
    assert!(spec["parallelism"].as_i64().unwrap() <= completions);
    let pod = at(spec, &["template", "spec"]);
    assert_eq!(text(&pod["restartPolicy"]), "Never");
    let container = &pod["containers"][0];
    let env = env_of(container);
    let tasks: i64 = env["TASKS"].parse().unwrap();
    let spp: u32 = env["SPP"].parse().unwrap();
    assert_eq!(tasks, completions, "TASKS is the job's completions");
    let script = text(&container["args"][0]);
    assert!(script.contains("$JOB_COMPLETION_INDEX"), "{script}");

    // Both jobs mount one claim at one path, where the parts go and are read from.
    let mount = |d: &Yaml| {
        let pod = at(d, &["spec", "template", "spec"]);
        let m = &pod["containers"][0]["volumeMounts"][0];
        let v = pod["volumes"]
            .as_vec()
            .unwrap()
            .iter()
            .find(|v| v["name"] == m["name"])
            .expect("the mounted volume");
        (
            text(&m["mountPath"]).to_string(),
            text(at(v, &["persistentVolumeClaim", "claimName"])).to_string(),
        )
    };
    assert_eq!(mount(render), mount(merge));
    let (dir, _) = mount(render);
    let merge_script = text(&merge["spec"]["template"]["spec"]["containers"][0]["args"][0]);
    assert!(
        merge_script.contains(&format!("tracery merge {dir}/part_")),
        "{merge_script}"
    );

    // Every index's pod, run with a stand-in `tracery`: the ranges cover 0..SPP once, each
    // part named by its index under the shared path.
    let bin = tempfile::tempdir().unwrap();
    let fake = bin.path().join("tracery");
    std::fs::write(&fake, "#!/bin/sh\necho \"$@\"\n").unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let shell = &container["command"];
    assert_eq!(text(&shell[0]), "/bin/sh");
    let mut next = 0u32;
    for k in 0..tasks {
        let out = Command::new(text(&shell[0]))
            .arg(text(&shell[1]))
            .arg(script)
            .envs(&env)
            .env("JOB_COMPLETION_INDEX", k.to_string())
            .env(
                "PATH",
                format!(
                    "{}:{}",
                    bin.path().display(),
                    std::env::var("PATH").unwrap()
                ),
            )
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let args = String::from_utf8(out.stdout).unwrap();
        let words: Vec<&str> = args.split_whitespace().collect();
        assert_eq!(words[0], "render");
        let range = words[words.iter().position(|w| *w == "--samples").unwrap() + 1];
        let output = words[words.iter().position(|w| *w == "-o").unwrap() + 1];
        let range = tracery::render::part::parse_range(range).unwrap();
        assert_eq!(range.start, next, "index {k}: {args}");
        assert_eq!(output, format!("{dir}/part_{k}.exr"));
        next = range.end;
    }
    assert_eq!(next, spp, "the ranges end at SPP");
}
