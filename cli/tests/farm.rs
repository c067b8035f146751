//! Farm rendering: the job lines of `tress farm`, run as separate processes, merge into the
//! single full render bit for bit; `tress merge` refuses pieces that do not belong together.

use crate::common::*;
use std::path::Path;
use std::process::Command;

/// Runs every line of `jobs` as its own shell process, all at once, and waits for them.
fn run_lines(jobs: &str, cwd: &Path) {
    let children: Vec<_> = jobs
        .lines()
        .map(|line| {
            Command::new("sh")
                .args(["-c", line])
                .current_dir(cwd)
                .spawn()
                .unwrap()
        })
        .collect();
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
}

fn farm(args: &[&str], cwd: &Path) -> String {
    let mut a = vec!["farm", "scene.ron"];
    a.extend_from_slice(args);
    let o = tress(&a, cwd);
    assert!(o.status.success(), "{}", stderr(&o));
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn tiles_times_passes_merge_into_the_full_render() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "full.exr", "--quiet"], d);
    let full = pixels(&d.join("full.exr"));
    for (tiles, passes) in [(3, 2), (1, 4), (5, 1), (2, 6)] {
        let (t, p) = (tiles.to_string(), passes.to_string());
        let out = format!("farm{tiles}x{passes}");
        let args = ["--tiles", t.as_str(), "--passes", p.as_str(), "--out", &out];
        let jobs = farm(&args, d);
        assert_eq!(jobs.lines().count(), tiles * passes, "{jobs}");
        run_lines(&jobs, d);
        let mut merge_args = args.to_vec();
        merge_args.push("--merge");
        let merge = farm(&merge_args, d);
        assert_eq!(merge.lines().count(), 1, "{merge}");
        run_lines(&merge, d);
        let merged = d.join(&out).join("scene.exr");
        assert_eq!(pixels(&merged), full, "{tiles} tiles x {passes} passes");
        assert_eq!(
            attribute(&merged, "tress:merged_from"),
            Some((tiles * passes).to_string())
        );
        assert_eq!(
            files_in(&d.join(&out)).len(),
            tiles * passes + 2,
            "pieces + merged EXR and PNG, no temporary files"
        );
    }
    // A scene with a crop window: the tiles split the window, the merge covers just that.
    std::fs::write(
        d.join("scene.ron"),
        SCENE.replace("seed: 3)", "seed: 3, crop: Some(2, 3, 20, 17))"),
    )
    .unwrap();
    render_ok(&["--out", "crop.exr", "--quiet"], d);
    let args = ["--tiles", "4", "--passes", "3", "--out", "cropfarm"];
    run_lines(&farm(&args, d), d);
    run_lines(&farm(&[&args[..], &["--merge"]].concat(), d), d);
    let merged = pixels(&d.join("cropfarm/scene.exr"));
    assert_eq!(merged.data_window, ([2, 3], [18, 14]));
    assert_eq!(merged, pixels(&d.join("crop.exr")));
    // Overrides reach every job; the default folder is named after the scene.
    let jobs = farm(
        &[
            "--tiles",
            "2",
            "--spp",
            "4",
            "--seed",
            "11",
            "--integrator",
            "Path(max_depth: 3)",
        ],
        d,
    );
    assert!(jobs.lines().all(|l| l.contains("--seed 11")
        && l.contains("--integrator 'Path(max_depth: 3)'")
        && l.contains("--spp 4")
        && l.contains("scene-farm/")));
}

/// The book's recipe (docs/src/guide/farms.md#render-farms) with a real engine: `tress farm … | parallel -j 2`, then the printed
/// merge piped to `sh`, gives the single full render bit for bit. GNU parallel is required, not
/// optional: `.ci/install-deps` installs it (Debian's `parallel`).
#[test]
fn a_farm_run_by_gnu_parallel_merges_into_the_full_render() {
    let version = Command::new("parallel").arg("--version").output();
    // moreutils ships another `parallel`, without `--version`: only GNU's will do.
    let is_gnu = version
        .as_ref()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).starts_with("GNU parallel"));
    assert!(
        is_gnu,
        "GNU parallel is not installed (found: {version:?}): run .ci/install-deps, or \
         apt-get install parallel"
    );
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "full.exr", "--quiet"], d);
    let farm = "\"$0\" farm scene.ron --tiles 3 --passes 2 --out pfarm";
    let o = Command::new("bash")
        .args([
            "-c",
            &format!("set -euo pipefail; {farm} | parallel -j 2; {farm} --merge | sh"),
            env!("CARGO_BIN_EXE_tress"),
        ])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let merged = d.join("pfarm/scene.exr");
    assert_eq!(pixels(&merged), pixels(&d.join("full.exr")));
    assert_eq!(
        attribute(&merged, "tress:merged_from"),
        Some("6".to_string())
    );
}

/// Daemons a test started: killed and reaped when it ends, passing or failing.
struct Daemons(Vec<std::process::Child>);

impl Drop for Daemons {
    fn drop(&mut self) {
        for child in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Fails, saying how to install it, unless `program` can be started.
fn require(program: &str, package: &str) {
    let o = Command::new(program).arg("--help").output();
    assert!(
        o.is_ok(),
        "{program} is not installed ({}): run .ci/install-deps, or apt-get install {package}",
        o.unwrap_err()
    );
}

/// A port nobody listens on now.
fn free_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().port()
}

/// The book's Slurm recipe on a one-node cluster of the test's own (munge with its own key
/// and socket, slurmctld and slurmd on free ports, all in a temporary folder): an array job of
/// the farm's lines, then the merge as a job depending on it, gives the single full render bit
/// for bit. Slurm is required, not optional: `.ci/install-deps` installs it (`slurm-wlm`).
#[test]
fn a_farm_run_as_a_slurm_array_job_merges_into_the_full_render() {
    for program in ["munged", "slurmctld", "slurmd", "sbatch", "sinfo", "squeue"] {
        require(program, "slurm-wlm");
    }
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "full.exr", "--quiet"], d);
    let args = ["--tiles", "3", "--passes", "2", "--out", "sfarm"];
    std::fs::write(d.join("jobs.txt"), farm(&args, d)).unwrap();
    std::fs::write(
        d.join("merge.sh"),
        farm(&[&args[..], &["--merge"]].concat(), d),
    )
    .unwrap();
    std::fs::write(
        d.join("render.sbatch"),
        "#!/bin/sh\n#SBATCH --array=1-6\n#SBATCH --cpus-per-task=1\n\
         sed -n \"${SLURM_ARRAY_TASK_ID}p\" jobs.txt | sh\n",
    )
    .unwrap();

    let s = d.join("slurm");
    std::fs::create_dir(&s).unwrap();
    let at = |name: &str| s.join(name).to_str().unwrap().to_string();
    let mut key = Vec::new();
    use std::io::Read;
    std::fs::File::open("/dev/urandom")
        .unwrap()
        .take(1024)
        .read_to_end(&mut key)
        .unwrap();
    std::fs::write(s.join("munge.key"), key).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(s.join("munge.key"), std::fs::Permissions::from_mode(0o600)).unwrap();
    let user = String::from_utf8(Command::new("id").arg("-un").output().unwrap().stdout).unwrap();
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    let host = host.trim().split('.').next().unwrap();
    let cpus = std::thread::available_parallelism().unwrap();
    // sched_interval=1: the scheduler looks at the queue every second rather than every
    // minute, so waiting array tasks and the merge start sooner (7 s for all, not 20).
    let conf = format!(
        "ClusterName=tress\nSlurmctldHost={host}(127.0.0.1)\nSlurmUser={user}\n\
         AuthType=auth/munge\nAuthInfo=socket={socket}\nStateSaveLocation={state}\n\
         SlurmdSpoolDir={state}/spool\nSlurmctldPidFile={state}/slurmctld.pid\n\
         SlurmdPidFile={state}/slurmd.pid\nSlurmctldPort={}\nSlurmdPort={}\n\
         SlurmctldLogFile={state}/slurmctld.log\nSlurmdLogFile={state}/slurmd.log\n\
         ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n\
         JobAcctGatherType=jobacct_gather/none\nMpiDefault=none\nReturnToService=2\n\
         SchedulerType=sched/builtin\nSchedulerParameters=sched_interval=1\n\
         SelectType=select/cons_tres\n\
         DependencyParameters=kill_invalid_depend\n\
         NodeName=tress-node NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN\n\
         PartitionName=farm Nodes=tress-node Default=YES MaxTime=INFINITE State=UP\n",
        free_port(),
        free_port(),
        user = user.trim(),
        socket = at("munge.socket"),
        state = s.display(),
    );
    std::fs::write(s.join("slurm.conf"), conf).unwrap();
    let log = |name: &str| std::fs::File::create(s.join(name)).unwrap();
    let daemon = |program: &str, args: &[String], out: &str| {
        Command::new(program)
            .args(args)
            .env("SLURM_CONF", s.join("slurm.conf"))
            .stdout(log(out))
            .stderr(log(out))
            .spawn()
            .unwrap()
    };
    let started = std::time::Instant::now();
    let mut daemons = Daemons(vec![daemon(
        "munged",
        &[
            "--foreground".into(),
            "--force".into(),
            format!("--key-file={}", at("munge.key")),
            format!("--socket={}", at("munge.socket")),
            format!("--pid-file={}", at("munged.pid")),
            format!("--log-file={}", at("munged.log")),
            format!("--seed-file={}", at("munged.seed")),
        ],
        "munged.out",
    )]);
    let conf = at("slurm.conf");
    let slurm = |program: &str, args: &[&str]| {
        Command::new(program)
            .args(args)
            .env("SLURM_CONF", &conf)
            .current_dir(d)
            .output()
            .unwrap()
    };
    // Waits up to `seconds` for `done`; on timeout fails with the daemons' logs.
    let wait = |what: &str, seconds: u64, done: &dyn Fn() -> bool| {
        let start = std::time::Instant::now();
        while !done() {
            if start.elapsed().as_secs() >= seconds {
                let logs: Vec<String> = files_in(&s)
                    .iter()
                    .filter(|f| f.ends_with(".log") || f.ends_with(".out"))
                    .map(|f| format!("--- {f}\n{}", std::fs::read_to_string(s.join(f)).unwrap()))
                    .collect();
                panic!("{what}: not after {seconds} s\n{}", logs.join("\n"));
            }
            std::thread::sleep(std::time::Duration::from_millis(250));
        }
    };
    wait("munged's socket", 30, &|| s.join("munge.socket").exists());
    daemons.0.push(daemon(
        "slurmctld",
        &["-D".into(), "-f".into(), conf.clone()],
        "slurmctld.out",
    ));
    daemons.0.push(daemon(
        "slurmd",
        &[
            "-D".into(),
            "-f".into(),
            conf.clone(),
            "-N".into(),
            "tress-node".into(),
        ],
        "slurmd.out",
    ));
    wait("the node idle", 60, &|| {
        String::from_utf8_lossy(&slurm("sinfo", &["-h", "-o", "%T"]).stdout).trim() == "idle"
    });
    let up = started.elapsed();
    let o = slurm("sbatch", &["--parsable", "render.sbatch"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let job = String::from_utf8(o.stdout).unwrap().trim().to_string();
    let after = format!("--dependency=afterok:{job}");
    let o = slurm("sbatch", &["--parsable", &after, "--wrap", "sh merge.sh"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A failed task cancels the merge (kill_invalid_depend), so the queue empties either way.
    wait("the queue empty", 300, &|| {
        slurm("squeue", &["-h"]).stdout.is_empty()
    });
    eprintln!(
        "slurm: up after {:.1} s, array and merge done after {:.1} s more",
        up.as_secs_f64(),
        (started.elapsed() - up).as_secs_f64()
    );
    let merged = d.join("sfarm/scene.exr");
    let outputs: Vec<String> = files_in(d)
        .iter()
        .filter(|f| f.starts_with("slurm-"))
        .map(|f| format!("--- {f}\n{}", std::fs::read_to_string(d.join(f)).unwrap()))
        .collect();
    assert!(
        merged.exists(),
        "no merged image; the jobs said:\n{}",
        outputs.join("\n")
    );
    assert_eq!(pixels(&merged), pixels(&d.join("full.exr")));
    assert_eq!(
        attribute(&merged, "tress:merged_from"),
        Some("6".to_string())
    );
}

/// `-D` reaches every job: a scene whose seed is a placeholder merges into the render with the
/// same define.
#[test]
fn farm_jobs_carry_the_scene_placeholders() {
    let (dir, _) = scene_dir(&SCENE.replace("seed: 3)", "seed: ${s})"));
    let d = dir.path();
    render_ok(&["--out", "full.exr", "-D", "s=7", "--quiet"], d);
    let args = ["--tiles", "2", "--passes", "2", "--out", "f", "-D", "s=7"];
    let jobs = farm(&args, d);
    assert!(jobs.lines().all(|l| l.contains("-D s=7")), "{jobs}");
    run_lines(&jobs, d);
    run_lines(&farm(&[&args[..], &["--merge"]].concat(), d), d);
    assert_eq!(pixels(&d.join("f/scene.exr")), pixels(&d.join("full.exr")));
    // Without the define the scene cannot be read, and farm says so.
    let o = tress(&["farm", "scene.ron", "--tiles", "2"], d);
    assert!(
        !o.status.success() && stderr(&o).contains("${s} has no value"),
        "{}",
        stderr(&o)
    );
}

/// Jobs write sums (the merge needs them) and pass alpha and the AOVs on; the merge rebuilds
/// every output channel bit for bit, with or without sums of its own.
#[test]
fn farm_jobs_carry_sums_and_outputs_and_merge_exactly() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let outputs = ["--alpha", "--aov", "variance,depth,albedo,tangent"];
    render_ok(
        &[&outputs[..], &["--out", "full.exr", "--quiet"]].concat(),
        d,
    );
    render_ok(
        &[
            &outputs[..],
            &["--out", "full_sums.exr", "--sums", "--quiet"],
        ]
        .concat(),
        d,
    );
    let args = [
        &["--tiles", "3", "--passes", "2", "--out", "f"],
        &outputs[..],
    ]
    .concat();
    let jobs = farm(&args, d);
    assert_eq!(jobs.lines().count(), 6, "{jobs}");
    for line in jobs.lines() {
        assert!(
            line.contains(" --sums ")
                && line.contains(" --alpha")
                && line.contains(" --aov depth,tangent,albedo,variance"),
            "{line}"
        );
    }
    run_lines(&jobs, d);
    let merge = farm(&[&args[..], &["--merge"]].concat(), d);
    assert!(
        !merge.contains("--sums"),
        "the final merge needs no sums: {merge}"
    );
    run_lines(&merge, d);
    let merged = pixels(&d.join("f/scene.exr"));
    assert_eq!(channel_names(&merged), EVERY_OUTPUT_CHANNEL);
    assert_eq!(merged, pixels(&d.join("full.exr")));
    // The merge keeps the pieces' camera and version.
    let header = |f: &str| tress_core::image_io::read_exr_attributes(d.join(f)).unwrap();
    let (full_header, merged_header) = (header("full.exr"), header("f/scene.exr"));
    for name in [
        "worldToCamera",
        "worldToNDC",
        "software",
        "tress:integrator",
    ] {
        let get = |h: &[(String, tress_core::image_io::Attribute)]| {
            h.iter().find(|a| a.0 == name).map(|a| a.1.clone())
        };
        assert!(get(&full_header).is_some(), "{name}");
        assert_eq!(get(&merged_header), get(&full_header), "{name}");
    }
    // Merged with --sums, it equals the single render with sums, and merges again.
    let pieces: Vec<String> = merge
        .split_whitespace()
        .skip(3)
        .take(6)
        .map(String::from)
        .collect();
    let o = tress(
        &[
            &["merge", "again.exr", "--sums", "--quiet"][..],
            &pieces.iter().map(String::as_str).collect::<Vec<_>>(),
        ]
        .concat(),
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        pixels(&d.join("again.exr")),
        pixels(&d.join("full_sums.exr"))
    );
    let o = tress(&["merge", "once_more.exr", "again.exr", "--quiet"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(pixels(&d.join("once_more.exr")), merged);
}

#[test]
fn bad_farm_requests_are_refused() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    for (args, expect) in [
        (vec!["--tiles", "0"], "--tiles 0"),
        (vec!["--tiles", "21"], "--tiles 21"),
        (vec!["--passes", "7"], "--passes 7"),
        (vec!["--passes", "0"], "--passes 0"),
        (vec!["--spp", "0"], "spp must be at least 1"),
        (vec!["--integrator", "bogus"], "bogus"),
        (vec!["--aov", "depth,bogus"], "unknown AOV 'bogus'"),
        // Forwarded to every job unchecked before: each job would have failed.
        (
            vec!["--threads", "100000"],
            "100000 worker threads: at most",
        ),
        (
            vec!["--out", "scene.ron"],
            "--out scene.ron: exists and is not a folder",
        ),
        (
            vec!["--tress", "./nowhere/tress"],
            "--tress ./nowhere/tress: not an executable file",
        ),
        (
            vec!["--tress", "./scene.ron"],
            "--tress ./scene.ron: not an executable file",
        ),
    ] {
        let mut a = vec!["farm", "scene.ron"];
        a.extend_from_slice(&args);
        let o = tress(&a, d);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert!(o.stdout.is_empty(), "{args:?}: printed jobs");
    }
    let o = tress(&["farm", "nowhere.ron"], d);
    assert!(!o.status.success() && stderr(&o).contains("nowhere.ron"));
}

#[test]
fn incompatible_pieces_are_refused_with_clear_errors() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    // (piece, extra arguments)
    let renders: [(&str, &[&str]); 8] = [
        ("top.exr", &["--crop", "0,0,24,10", "--spp", "4"]),
        ("bottom.exr", &["--crop", "0,10,24,20", "--spp", "4"]),
        (
            "more_top.exr",
            &["--crop", "0,0,24,10", "--spp-offset", "4", "--spp", "4"],
        ),
        (
            "late_bottom.exr",
            &["--crop", "0,10,24,20", "--spp-offset", "6", "--spp", "2"],
        ),
        ("middle.exr", &["--crop", "0,5,24,15", "--spp", "4"]),
        (
            "top_seed.exr",
            &["--crop", "0,0,24,10", "--spp", "4", "--seed", "4"],
        ),
        (
            "top_overlap.exr",
            &["--crop", "0,0,24,10", "--spp-offset", "2", "--spp", "4"],
        ),
        (
            "top_other.exr",
            &[
                "--crop",
                "0,0,24,10",
                "--spp",
                "4",
                "--integrator",
                "Path(max_depth: 2)",
            ],
        ),
    ];
    for (out, extra) in renders {
        render_ok(
            &[&["--out", out, "--sums", "--no-preview", "--quiet"], extra].concat(),
            d,
        );
    }
    // Pieces without sums, or recording other outputs.
    let without_sums = ["--crop", "0,10,24,20", "--spp", "4", "--out", "no_sums.exr"];
    render_ok(&[&without_sums[..], &["--quiet"]].concat(), d);
    let with_alpha = ["--crop", "0,10,24,20", "--spp", "4", "--out", "alpha.exr"];
    render_ok(
        &[&with_alpha[..], &["--sums", "--alpha", "--quiet"]].concat(),
        d,
    );
    std::fs::write(
        d.join("big.ron"),
        SCENE.replace("width: 24, height: 20", "width: 24, height: 30"),
    )
    .unwrap();
    let o = tress(
        &[
            "render",
            "big.ron",
            "--crop",
            "0,10,24,20",
            "--spp",
            "4",
            "--out",
            "big.exr",
            "--sums",
            "--quiet",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut plain = tress_core::Image::new(24, 20);
    plain
        .pixels
        .iter_mut()
        .for_each(|p| *p = tress_core::Rgb::ONE);
    to_file(d.join("plain.exr"), |o| {
        tress_core::image_io::write_exr(o, &plain, &[])
    })
    .unwrap();
    std::fs::write(d.join("junk.exr"), b"not an exr").unwrap();
    // A piece whose pixel values were changed after rendering.
    {
        use exr::prelude::*;
        let mut img = read_first_flat_layer_from_file(d.join("top.exr")).unwrap();
        for c in img.layer_data.channel_data.list.iter_mut() {
            if c.name.to_string() == "G" {
                if let FlatSamples::F32(v) = &mut c.sample_data {
                    v[7] += 1.0;
                }
            }
        }
        img.write().to_file(d.join("edited.exr")).unwrap();
    }

    // (pieces, extra arguments, what the message must say)
    let refused: [(&[&str], &[&str], &[&str]); 15] = [
        (
            &["top.exr", "no_sums.exr"],
            &[],
            &["no_sums.exr", "no sample sums", "tress render --sums"],
        ),
        (
            &["top.exr", "alpha.exr"],
            &[],
            &["alpha.exr", "differs (R, G, B vs R, G, B, A)", "--alpha"],
        ),
        (
            &["top.exr", "top_seed.exr"],
            &[],
            &["top_seed.exr", "seed differs (3 vs 4)"],
        ),
        (
            &["top.exr", "top_other.exr"],
            &[],
            &["top_other.exr", "scene"],
        ),
        (
            &["top.exr", "big.exr"],
            &[],
            &["big.exr", "film size differs (24x20 vs 24x30)"],
        ),
        (
            &["top.exr", "bottom.exr", "top_overlap.exr"],
            &[],
            &["top_overlap.exr", "overlap"],
        ),
        (
            &["top.exr", "middle.exr", "bottom.exr"],
            &[],
            &["middle.exr", "tiles overlap"],
        ),
        (
            &["top.exr", "more_top.exr"],
            &["--crop", "0,0,24,20"],
            &["no piece covers pixel (0, 10)", "a tile is missing"],
        ),
        (
            &["top.exr", "bottom.exr", "more_top.exr"],
            &[],
            &["pixel (0, 10) with samples [4, 8)", "a tile is missing"],
        ),
        (
            &["top.exr", "bottom.exr", "late_bottom.exr"],
            &[],
            &["samples [4, 6) are missing"],
        ),
        (
            &["top.exr", "bottom.exr"],
            &["--expect-spp", "8"],
            &["4 per pixel, but 8 were expected"],
        ),
        (
            &["top.exr", "plain.exr"],
            &[],
            &["plain.exr", "no sample sums"],
        ),
        (&["top.exr", "junk.exr"], &[], &["junk.exr", "OpenEXR"]),
        (
            &["top.exr", "absent.exr"],
            &[],
            &["absent.exr", "not found"],
        ),
        (
            &["edited.exr", "bottom.exr"],
            &[],
            &["edited.exr", "pixel (7, 0)", "modified"],
        ),
    ];
    for (pieces, extra, expect) in refused {
        let mut a = vec!["merge", "out.exr"];
        a.extend_from_slice(pieces);
        a.extend_from_slice(extra);
        let o = tress(&a, d);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{pieces:?}: {err}");
        for e in expect {
            assert!(err.contains(e), "{pieces:?}: message lacks '{e}': {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!d.join("out.exr").exists() && !d.join("out.png").exists());
    }
    let o = tress(&["merge", "out.png", "top.exr"], d);
    assert!(!o.status.success() && stderr(&o).contains("out.png"));
    let o = tress(&["merge", "out.exr"], d);
    assert!(!o.status.success(), "merging nothing must fail");
}
