//! No write can leave a partial file where a good one was (issue 23): the
//! `lantern` binary renders onto an existing image with its file-size
//! limit (`RLIMIT_FSIZE`) lowered, so that every write past a few hundred
//! bytes fails with `EFBIG` as on a full disk. The old image must be
//! byte-identical afterwards, no temporary file may be left, and the
//! message must name the file and say that it was kept.

#![cfg(unix)]

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A small sun-lit sphere: renders in a fraction of a second.
const SCENE: &str = r#"(
    camera: (eye: (0.0, 0.0, 3.5), target: (0.0, 0.0, 0.0), up: (0.0, 1.0, 0.0), fov_y_deg: 40.0, width: 24, height: 24),
    medium: (
        density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0),
        sigma_t: (1.0, 1.0, 1.0),
        albedo: (0.9, 0.9, 0.9),
        g: 0.5,
    ),
    lights: [Sun(direction: (0.6, -1.0, -0.5), irradiance: (3.0, 3.0, 3.0))],
    render: (method: Reference, spp: 2, seed: 0),
)"#;

/// The bytes of the "previous good image": anything recognisable.
fn previous_image() -> Vec<u8> {
    (0..5000u32).map(|i| (i * 7 % 251) as u8).collect()
}

/// Runs `lantern ARGS` with its file-size limit at `fsize` bytes (if any),
/// SIGXFSZ ignored so that writes fail with EFBIG instead of killing it.
fn lantern(args: &[&str], dir: &Path, fsize: Option<u64>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_lantern"));
    cmd.args(args).current_dir(dir);
    if let Some(limit) = fsize {
        // SAFETY: between fork and exec only async-signal-safe calls
        // (signal, setrlimit) on this process's own state.
        unsafe {
            cmd.pre_exec(move || {
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                let lim = libc::rlimit {
                    rlim_cur: limit as libc::rlim_t,
                    rlim_max: limit as libc::rlim_t,
                };
                if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    cmd.output().expect("lantern runs")
}

fn setup() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.ron");
    std::fs::write(&scene, SCENE).unwrap();
    (dir, scene)
}

fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect()
}

/// A render onto `name` that cannot write keeps the previous file.
fn render_on_a_full_disk_keeps(name: &str) {
    let (dir, _) = setup();
    let target = dir.path().join(name);
    std::fs::write(&target, previous_image()).unwrap();
    let out = lantern(
        &["render", "scene.ron", "--out", name],
        dir.path(),
        Some(256),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the write cannot succeed: {stderr}");
    assert_eq!(
        std::fs::read(&target).unwrap(),
        previous_image(),
        "{name} was changed: {stderr}"
    );
    assert!(
        temp_files(dir.path()).is_empty(),
        "{:?}",
        temp_files(dir.path())
    );
    assert!(
        stderr.contains(name) && stderr.contains("kept unchanged"),
        "the message must name {name} and say it was kept: {stderr}"
    );
}

#[test]
fn a_failed_exr_write_keeps_the_previous_image() {
    render_on_a_full_disk_keeps("image.exr");
}

#[test]
fn a_failed_png_write_keeps_the_previous_image() {
    render_on_a_full_disk_keeps("image.png");
}

/// A symbolic link at the output survives a failed write (the EXR encoder
/// once removed it) and a successful one (written through the link).
#[test]
fn a_symbolic_link_at_the_output_survives() {
    let (dir, _) = setup();
    let real = dir.path().join("real.exr");
    std::fs::write(&real, previous_image()).unwrap();
    let link = dir.path().join("link.exr");
    std::os::unix::fs::symlink("real.exr", &link).unwrap();
    let is_link = |p: &Path| {
        std::fs::symlink_metadata(p)
            .map(|m| m.file_type().is_symlink())
            .unwrap_or(false)
    };
    let out = lantern(
        &["render", "scene.ron", "--out", "link.exr"],
        dir.path(),
        Some(256),
    );
    assert!(!out.status.success());
    assert!(is_link(&link), "the link was removed");
    assert_eq!(std::fs::read(&real).unwrap(), previous_image());
    let out = lantern(
        &["render", "scene.ron", "--out", "link.exr"],
        dir.path(),
        None,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(is_link(&link), "the link was replaced by a file");
    let written = std::fs::read(&real).unwrap();
    assert_ne!(written, previous_image());
    assert_eq!(&written[..4], &[0x76, 0x2f, 0x31, 0x01], "an EXR file");
    assert!(temp_files(dir.path()).is_empty());
}

/// `lantern converge` keeps its earlier `converged.exr` when it cannot
/// write a new one.
#[test]
fn converge_keeps_its_previous_outputs() {
    let (dir, _) = setup();
    let out_dir = dir.path().join("conv");
    let args = [
        "converge",
        "scene.ron",
        "--size",
        "16",
        "--reference-spp",
        "1",
        "--budget",
        "0.05",
        "--out",
        "conv",
    ];
    // The output folder is `conv/<scene stem>`.
    let run = lantern(&args, dir.path(), None);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let converged = out_dir.join("scene").join("converged.exr");
    let before = std::fs::read(&converged).unwrap();
    let run = lantern(&args, dir.path(), Some(256));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert_eq!(std::fs::read(&converged).unwrap(), before, "{stderr}");
    assert!(stderr.contains("kept unchanged"), "{stderr}");
    assert!(temp_files(&out_dir.join("scene")).is_empty());
}

/// A missing output folder is reported before any work: the internal
/// lights are not even built (their line is printed before the render).
#[test]
fn a_missing_output_folder_is_reported_before_the_render() {
    let (dir, _) = setup();
    let out = lantern(
        &[
            "render",
            "scene.ron",
            "--method",
            "internal",
            "--out",
            "no/such/folder/x.exr",
        ],
        dir.path(),
        None,
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        !stdout.contains("internal lights"),
        "work started before the check: {stdout}"
    );
    assert!(
        stderr.contains("no/such/folder") && stderr.contains("does not exist"),
        "{stderr}"
    );
}
