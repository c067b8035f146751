//! Helpers shared by the tests of the `tress` binary: running it, small scenes, and reading
//! every channel of an EXR bit for bit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use tress_core::image_io::ImageError;
use tress_core::output_file::{Inputs, Sink};

/// Runs `tress` with `args` in `cwd`. Its default table cache is a folder of the build's
/// (`XDG_CACHE_HOME` under `CARGO_TARGET_TMPDIR`), not the user's.
pub fn tress(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tress"))
        .env(
            "XDG_CACHE_HOME",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-tests-cache"),
        )
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run tress")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `tress render scene.ron` with `args` in `cwd`, which must succeed; returns its stderr.
pub fn render_ok(args: &[&str], cwd: &Path) -> String {
    let o = tress(&[&["render", "scene.ron"], args].concat(), cwd);
    assert!(o.status.success(), "{}", stderr(&o));
    stderr(&o)
}

/// Writes one file at `path` with `write`, through tress's own writer.
pub fn to_file(
    path: impl AsRef<Path>,
    write: impl FnOnce(&mut Sink) -> Result<(), ImageError>,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    tress_core::output_file::write(path.as_ref(), &Inputs::default(), |out| {
        write(out).map_err(Box::from)
    })
}

/// A tiny scene that renders in milliseconds: procedural hair ball, a sphere, sky and sun.
pub const SCENE: &str = r#"(
    camera: (look_from: (0, 0, 4), look_at: (0, 0, 0), fov: 35),
    film: (width: 24, height: 20, spp: 6, seed: 3),
    integrator: Path(max_depth: 20),
    materials: {
        "hair": Hair(Chiang(beta_m: 0.3, beta_n: 0.3, pigment: Melanin(eumelanin: 1.0))),
        "grey": Diffuse(albedo: (0.5, 0.5, 0.5)),
    },
    objects: [
        Hair(source: Procedural(style: Ball, strands: 300, radius: 0.01), material: "hair"),
        Sphere(center: (0, -2, 0), radius: 1, material: "grey"),
    ],
    lights: [Sky(), Distant(direction: (0, -1, -1), irradiance: (2, 2, 2), angular_radius: 0.5)],
)"#;

/// A temporary folder holding `scene.ron` with `text`.
pub fn scene_dir(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.ron");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

/// The file names in `dir`, sorted.
pub fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The pixel content of an EXR: data window, display window, and every channel's name and
/// sample bits (R, G, B and the sample-sum channels).
#[derive(Debug, PartialEq)]
pub struct Pixels {
    pub data_window: ([i32; 2], [usize; 2]),
    pub display: [usize; 2],
    pub channels: Vec<(String, Vec<u32>)>,
}

/// The channel names, in the EXR's (alphabetical) order.
pub fn channel_names(p: &Pixels) -> Vec<&str> {
    p.channels.iter().map(|c| c.0.as_str()).collect()
}

/// The channels of a render with `--alpha --aov depth,tangent,albedo,variance`, in order.
pub const EVERY_OUTPUT_CHANNEL: [&str; 14] = [
    "A",
    "B",
    "G",
    "R",
    "albedo.B",
    "albedo.G",
    "albedo.R",
    "depth.Z",
    "tangent.X",
    "tangent.Y",
    "tangent.Z",
    "variance.B",
    "variance.G",
    "variance.R",
];

pub fn pixels(path: &Path) -> Pixels {
    use exr::prelude::*;
    let image = read_first_flat_layer_from_file(path).unwrap();
    let layer = &image.layer_data;
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let bits = match &c.sample_data {
                FlatSamples::F32(v) => v.iter().map(|x| x.to_bits()).collect(),
                FlatSamples::U32(v) => v.clone(),
                FlatSamples::F16(v) => v.iter().map(|x| x.to_bits() as u32).collect(),
            };
            (c.name.to_string(), bits)
        })
        .collect();
    let pos = layer.attributes.layer_position;
    Pixels {
        data_window: (
            [pos.x(), pos.y()],
            [layer.size.width(), layer.size.height()],
        ),
        display: [
            image.attributes.display_window.size.width(),
            image.attributes.display_window.size.height(),
        ],
        channels,
    }
}

/// A text attribute of a tress EXR.
pub fn attribute(path: &Path, name: &str) -> Option<String> {
    let (_, attrs) = tress_core::image_io::read_exr(path).unwrap();
    attrs.into_iter().find(|(k, _)| k == name).map(|(_, v)| v)
}
