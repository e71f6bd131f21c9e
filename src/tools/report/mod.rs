//! `voxtrace report`: speed against error.
//!
//! Every scene of a fixed suite ([`suite`]) is rendered under variants —
//! precision, recursion depth, samples per pixel, the adaptive cut-off, the
//! index — and each image is compared with a high-quality reference of the
//! same scene: f64, brute-force search, depth 16, and 256 samples per pixel
//! where sampling is the variable. Timings are medians of interleaved
//! repetitions. The result is `report.md` and a plot of time against error
//! per scene family with the Pareto front marked ([`plot`]).

mod markdown;
mod metrics;
mod plot;
pub mod suite;

pub use metrics::{mismatch_rate, ImageError};
pub use suite::{Family, SuiteScene};

use crate::names::Named;
use crate::render::{
    eye_hit_map, eye_hit_map_from, render_in, IndexKind, RayCounts, RenderOptions,
};
use crate::scene::{Camera, Scene};
use glam::DVec3;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to render and where the report goes.
#[derive(Clone, Debug)]
pub struct ReportConfig {
    /// Where report.md and the plot go.
    pub out: PathBuf,
    /// The course's reference scenes (with classic/ and tinygraphics/).
    pub reference: PathBuf,
    /// The hard-case scenes.
    pub hard: PathBuf,
    /// Timed repetitions of each variant (the median is reported).
    pub reps: u32,
    /// Longest image side for the antialiasing part (its reference traces
    /// [`REFERENCE_SPP`] samples per pixel, so it runs at reduced resolution).
    pub aa_size: u32,
    /// Which scene families to render.
    pub families: Vec<Family>,
}

#[derive(Debug)]
pub enum ReportError {
    Suite(suite::SuiteError),
    Render {
        scene: String,
        error: crate::render::RenderError,
    },
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
    Plot(String),
    /// The report was written, but an index disagreed with brute force.
    IndexNotExact(Vec<String>),
}

impl fmt::Display for ReportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReportError::Suite(e) => write!(f, "{e}"),
            ReportError::Render { scene, error } => write!(f, "{scene}: {error}"),
            ReportError::Write { path, error } => {
                write!(f, "cannot write {}: {error}", path.display())
            }
            ReportError::Plot(why) => write!(f, "cannot draw the plot: {why}"),
            ReportError::IndexNotExact(rows) => {
                write!(f, "an index differs from brute force: {}", rows.join("; "))
            }
        }
    }
}

impl std::error::Error for ReportError {}

/// Which part of the report a variant belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Section {
    Precision,
    Recursion,
    Antialiasing,
    Cutoff,
    Index,
}

impl fmt::Display for Section {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Section::Precision => "precision",
            Section::Recursion => "recursion",
            Section::Antialiasing => "antialiasing",
            Section::Cutoff => "cut-off",
            Section::Index => "index",
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

/// What a variant's image is compared with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Against {
    /// f64, brute force, depth 16, one sample per pixel, full resolution.
    Reference,
    /// The same at reduced resolution with 256 samples per pixel.
    SampledReference,
    /// Brute force in the same precision and settings: an index must match it exactly.
    BruteForce,
}

/// One way of rendering a scene.
#[derive(Clone, Debug)]
pub struct Variant {
    pub section: Section,
    pub label: String,
    pub precision: Precision,
    pub spp: u32,
    pub depth: u32,
    pub cutoff: bool,
    pub index: IndexKind,
    /// Whether the precision rule refines f32 hit points.
    pub refine: bool,
    pub against: Against,
}

/// The f32 variant without the precision rule (plain f32 hit points).
pub const PLAIN_F32: &str = "f32 without the precision rule";

/// The reference's recursion depth ("deep": every variant's is at most this).
pub const REFERENCE_DEPTH: u32 = 16;
/// The reference's samples per pixel in the antialiasing part.
pub const REFERENCE_SPP: u32 = 256;
const DEPTHS: [u32; 5] = [1, 2, 3, 5, 8];
const SAMPLES: [u32; 4] = [1, 4, 16, 64];

impl Variant {
    fn new(section: Section, label: String, precision: Precision, against: Against) -> Self {
        Variant {
            section,
            label,
            precision,
            spp: 1,
            depth: REFERENCE_DEPTH,
            cutoff: false,
            index: IndexKind::Brute,
            refine: true,
            against,
        }
    }

    fn options(&self) -> RenderOptions {
        RenderOptions {
            spp: self.spp,
            depth: Some(self.depth),
            adaptive_cutoff: self.cutoff,
            index: self.index,
            refine: self.refine,
            ..RenderOptions::default()
        }
    }

    /// Whether its eye rays are the reference's, so hit maps compare.
    fn one_sample(&self) -> bool {
        self.spp == 1 && self.against != Against::SampledReference
    }
}

/// The variants, the first of each part being its reference.
pub fn variants() -> Vec<Variant> {
    use Precision::{F32, F64};
    let mut v = vec![
        Variant::new(
            Section::Precision,
            "f64 (reference)".into(),
            F64,
            Against::Reference,
        ),
        Variant::new(Section::Precision, "f32".into(), F32, Against::Reference),
        Variant {
            refine: false,
            ..Variant::new(
                Section::Precision,
                PLAIN_F32.into(),
                F32,
                Against::Reference,
            )
        },
    ];
    for depth in DEPTHS {
        v.push(Variant {
            depth,
            ..Variant::new(
                Section::Recursion,
                format!("f32 depth {depth}"),
                F32,
                Against::Reference,
            )
        });
    }
    v.push(Variant {
        cutoff: true,
        ..Variant::new(
            Section::Cutoff,
            "f32 + cut-off".into(),
            F32,
            Against::Reference,
        )
    });
    v.push(Variant {
        depth: 3,
        cutoff: true,
        ..Variant::new(
            Section::Cutoff,
            "f32 depth 3 + cut-off".into(),
            F32,
            Against::Reference,
        )
    });
    for &index in IndexKind::ALL {
        v.push(Variant {
            index,
            ..Variant::new(
                Section::Index,
                format!("f32 index {index}"),
                F32,
                Against::BruteForce,
            )
        });
        v.push(Variant {
            index,
            ..Variant::new(
                Section::Index,
                format!("f64 index {index}"),
                F64,
                Against::BruteForce,
            )
        });
    }
    v.push(Variant {
        spp: REFERENCE_SPP,
        ..Variant::new(
            Section::Antialiasing,
            format!("f64 spp {REFERENCE_SPP} (reference)"),
            F64,
            Against::SampledReference,
        )
    });
    for spp in SAMPLES {
        v.push(Variant {
            spp,
            ..Variant::new(
                Section::Antialiasing,
                format!("f32 spp {spp}"),
                F32,
                Against::SampledReference,
            )
        });
    }
    v
}

/// One variant of one scene, measured.
#[derive(Clone, Debug)]
pub struct Measurement {
    pub scene: String,
    pub family: Family,
    pub variant: usize,
    /// Median of build + render time, seconds.
    pub seconds: f64,
    pub mrays_per_second: f64,
    pub rays: RayCounts,
    pub error: ImageError,
    /// The image size it was rendered at.
    pub size: (u32, u32),
    /// For the cut-off: how the image differs from the same render without it.
    pub diff_from_uncut: Option<ImageError>,
}

/// The same scene with its longest side at most `size` pixels (same frame).
fn reduced(scene: &Scene, size: u32) -> Scene {
    let Camera { width, height, .. } = scene.camera;
    let longest = width.max(height);
    let mut s = scene.clone();
    if longest > size {
        s.camera.width = (u64::from(width) * u64::from(size) / u64::from(longest)).max(1) as u32;
        s.camera.height = (u64::from(height) * u64::from(size) / u64::from(longest)).max(1) as u32;
    }
    s
}

/// The timed repetitions of one variant, and the image they all rendered.
struct Runs {
    image: crate::output::Image,
    rays: RayCounts,
    seconds: Vec<f64>,
    render_seconds: Vec<f64>,
}

fn render_once(
    scene: &Scene,
    name: &str,
    v: &Variant,
) -> Result<crate::render::Rendered, ReportError> {
    let options = v.options();
    let result = match v.precision {
        Precision::F32 => render_in::<f32>(scene, &options, &|_| {}),
        Precision::F64 => render_in::<f64>(scene, &options, &|_| {}),
    };
    result.map_err(|error| ReportError::Render {
        scene: name.to_owned(),
        error,
    })
}

type MapKey = (Precision, IndexKind);
type HitMap = Vec<Option<u32>>;

/// Renders every variant of one scene `reps` times, interleaved, and measures each.
fn measure_scene(
    entry: &SuiteScene,
    variants: &[Variant],
    reps: u32,
    aa_size: u32,
) -> Result<Vec<Measurement>, ReportError> {
    let small = reduced(&entry.scene, aa_size);
    let scene_for = |v: &Variant| {
        if v.section == Section::Antialiasing {
            &small
        } else {
            &entry.scene
        }
    };
    let mut runs: Vec<Option<Runs>> = variants.iter().map(|_| None).collect();
    for rep in 0..reps.max(1) {
        for (v, run) in variants.iter().zip(&mut runs) {
            // The 256-sample reference costs more than everything else
            // together; it is timed once.
            if rep > 0 && v.spp >= REFERENCE_SPP {
                continue;
            }
            let started = Instant::now();
            let r = render_once(scene_for(v), &entry.name, v)?;
            let wall = started.elapsed().as_secs_f64();
            let run = run.get_or_insert_with(|| Runs {
                image: r.image.clone(),
                rays: r.stats.rays,
                seconds: vec![],
                render_seconds: vec![],
            });
            debug_assert_eq!(run.image, r.image, "renders are deterministic");
            run.seconds.push(wall);
            run.render_seconds.push(r.stats.render_time.as_secs_f64());
        }
    }
    let runs: Vec<Runs> = runs
        .into_iter()
        .map(|r| r.expect("at least one repetition"))
        .collect();
    let reference = position(variants, |v| v.against == Against::Reference);
    let sampled = position(variants, |v| v.against == Against::SampledReference);
    let brute = |p: Precision| {
        position(variants, |v| {
            v.section == Section::Index && v.precision == p && v.index == IndexKind::Brute
        })
    };
    // Nearest-sphere maps, computed once per precision and index.
    let mut maps: Vec<(MapKey, HitMap)> = vec![];
    let mut map = |precision: Precision, index: IndexKind| -> Vec<Option<u32>> {
        if let Some((_, m)) = maps.iter().find(|(key, _)| *key == (precision, index)) {
            return m.clone();
        }
        let m = match precision {
            Precision::F32 => eye_hit_map::<f32>(&entry.scene, index),
            Precision::F64 => eye_hit_map::<f64>(&entry.scene, index),
        };
        maps.push(((precision, index), m.clone()));
        m
    };
    let reference_map = map(Precision::F64, IndexKind::Brute);
    let mut out = vec![];
    for (i, (v, run)) in variants.iter().zip(&runs).enumerate() {
        let base = match v.against {
            Against::Reference => reference,
            Against::SampledReference => sampled,
            Against::BruteForce => brute(v.precision),
        };
        let mut error = ImageError::between(&run.image, &runs[base].image);
        if v.one_sample() {
            let against_map = match v.against {
                Against::BruteForce => map(v.precision, IndexKind::Brute),
                _ => reference_map.clone(),
            };
            error.hit_mismatch = Some(mismatch_rate(&map(v.precision, v.index), &against_map));
        }
        let uncut = variants.iter().position(|u| {
            v.cutoff
                && !u.cutoff
                && u.section != Section::Index
                && u.refine == v.refine
                && (u.precision, u.depth, u.spp, u.index) == (v.precision, v.depth, v.spp, v.index)
        });
        let diff_from_uncut = uncut.map(|u| ImageError::between(&run.image, &runs[u].image));
        let render = metrics::median(run.render_seconds.clone());
        out.push(Measurement {
            scene: entry.name.clone(),
            family: entry.family,
            variant: i,
            seconds: metrics::median(run.seconds.clone()),
            mrays_per_second: run.rays.total() as f64 / render.max(1e-9) / 1e6,
            rays: run.rays,
            error,
            size: (run.image.width, run.image.height),
            diff_from_uncut,
        });
    }
    Ok(out)
}

fn position(variants: &[Variant], pred: impl Fn(&Variant) -> bool) -> usize {
    variants
        .iter()
        .position(pred)
        .expect("the variant list has every reference")
}

/// The hit-map check of the moved and scaled copies of `hard/base.txt`.
#[derive(Clone, Debug)]
pub struct Invariance {
    pub name: String,
    pub f32_mismatch: f64,
    pub f64_mismatch: f64,
}

fn invariance(hard: &Path) -> Result<Vec<Invariance>, ReportError> {
    let base = suite::load_scene(&hard.join("base.txt")).map_err(ReportError::Suite)?;
    let original = eye_hit_map::<f64>(&base, IndexKind::Brute);
    let mut out = vec![];
    for (name, eye) in [
        ("translated_1e5", 1e5),
        ("translated_1e7", 1e7),
        ("scaled_1e-4", 0.0),
        ("scaled_1e4", 0.0),
    ] {
        let scene =
            suite::load_scene(&hard.join(format!("{name}.txt"))).map_err(ReportError::Suite)?;
        let eye = DVec3::splat(eye);
        out.push(Invariance {
            name: name.to_owned(),
            f32_mismatch: mismatch_rate(
                &eye_hit_map_from::<f32>(&scene, IndexKind::Brute, eye),
                &original,
            ),
            f64_mismatch: mismatch_rate(
                &eye_hit_map_from::<f64>(&scene, IndexKind::Brute, eye),
                &original,
            ),
        });
    }
    Ok(out)
}

/// Everything the report shows.
pub struct Report {
    pub variants: Vec<Variant>,
    pub measurements: Vec<Measurement>,
    pub invariance: Vec<Invariance>,
    pub threads: usize,
    pub reps: u32,
    pub aa_size: u32,
    pub seconds: f64,
}

/// Renders the suite `config` names and writes the report, on the current
/// rayon pool (scenes are parsed there too).
pub fn run(config: &ReportConfig) -> Result<(), ReportError> {
    let started = Instant::now();
    let suite = suite::load(&config.reference, &config.hard, &config.families)
        .map_err(ReportError::Suite)?;
    let variants = variants();
    let mut measurements = vec![];
    for (i, entry) in suite.iter().enumerate() {
        eprintln!("[{}/{}] {}", i + 1, suite.len(), entry.name);
        measurements.extend(measure_scene(
            entry,
            &variants,
            config.reps,
            config.aa_size,
        )?);
    }
    let invariance = invariance(&config.hard)?;
    let report = Report {
        variants,
        measurements,
        invariance,
        threads: rayon::current_num_threads(),
        reps: config.reps,
        aa_size: config.aa_size,
        seconds: started.elapsed().as_secs_f64(),
    };
    std::fs::create_dir_all(&config.out).map_err(|error| ReportError::Write {
        path: config.out.clone(),
        error,
    })?;
    let plot_path = config.out.join(plot::FILE_NAME);
    plot::draw(&report, &plot_path)?;
    let md_path = config.out.join("report.md");
    std::fs::write(&md_path, markdown::write(&report)).map_err(|error| ReportError::Write {
        path: md_path.clone(),
        error,
    })?;
    eprintln!(
        "wrote {} and {} in {:.0} s",
        md_path.display(),
        plot_path.display(),
        report.seconds
    );
    let inexact: Vec<String> = report
        .measurements
        .iter()
        .filter(|m| {
            report.variants[m.variant].against == Against::BruteForce && !m.error.is_exact()
        })
        .map(|m| format!("{} {}", m.scene, report.variants[m.variant].label))
        .collect();
    if inexact.is_empty() {
        Ok(())
    } else {
        Err(ReportError::IndexNotExact(inexact))
    }
}

/// One variant over one family of scenes.
#[derive(Clone, Debug)]
pub struct Summary {
    pub variant: usize,
    /// Sum over the family's scenes of the median time, seconds.
    pub seconds: f64,
    /// Rays over render time, all scenes together.
    pub mrays_per_second: f64,
    pub mean_rmse: f64,
    pub worst_max_diff: u8,
    pub mean_off_by_more_than_one: f64,
    pub mean_hit_mismatch: Option<f64>,
    /// Whether no other variant of the same comparison is both faster and
    /// more accurate.
    pub pareto: bool,
}

impl Report {
    /// The families that were rendered, in their fixed order.
    pub fn families(&self) -> Vec<Family> {
        Family::ALL
            .iter()
            .copied()
            .filter(|f| self.measurements.iter().any(|m| m.family == *f))
            .collect()
    }

    /// Every variant over `family`, with the Pareto front marked among the
    /// variants compared with the same reference.
    pub fn summarize(&self, family: Family) -> Vec<Summary> {
        let mut out: Vec<Summary> = (0..self.variants.len())
            .filter_map(|variant| {
                let ms: Vec<&Measurement> = self
                    .measurements
                    .iter()
                    .filter(|m| m.family == family && m.variant == variant)
                    .collect();
                let n = ms.len() as f64;
                if ms.is_empty() {
                    return None;
                }
                let rays: u64 = ms.iter().map(|m| m.rays.total()).sum();
                let render: f64 = ms
                    .iter()
                    .map(|m| m.rays.total() as f64 / (m.mrays_per_second * 1e6).max(1e-9))
                    .sum();
                let mismatches: Vec<f64> = ms.iter().filter_map(|m| m.error.hit_mismatch).collect();
                Some(Summary {
                    variant,
                    seconds: ms.iter().map(|m| m.seconds).sum(),
                    mrays_per_second: rays as f64 / render.max(1e-9) / 1e6,
                    mean_rmse: ms.iter().map(|m| m.error.rmse).sum::<f64>() / n,
                    worst_max_diff: ms.iter().map(|m| m.error.max_diff).max().unwrap_or(0),
                    mean_off_by_more_than_one: ms
                        .iter()
                        .map(|m| m.error.off_by_more_than_one)
                        .sum::<f64>()
                        / n,
                    mean_hit_mismatch: (mismatches.len() == ms.len())
                        .then(|| mismatches.iter().sum::<f64>() / n),
                    pareto: false,
                })
            })
            .collect();
        let points: Vec<(f64, f64, Against)> = out
            .iter()
            .map(|s| (s.seconds, s.mean_rmse, self.variants[s.variant].against))
            .collect();
        for (s, &(t, e, against)) in out.iter_mut().zip(&points) {
            s.pareto = against != Against::BruteForce
                && !points
                    .iter()
                    .any(|&(t2, e2, a2)| a2 == against && t2 <= t && e2 <= e && (t2 < t || e2 < e));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_part_has_its_reference_and_every_index_is_compared() {
        let v = variants();
        assert_eq!(
            v.iter()
                .filter(|v| v.against == Against::Reference && v.precision == Precision::F64)
                .count(),
            1
        );
        for &index in IndexKind::ALL {
            assert_eq!(
                v.iter()
                    .filter(|v| v.section == Section::Index && v.index == index)
                    .count(),
                2
            );
        }
        let depths: Vec<u32> = v
            .iter()
            .filter(|v| v.section == Section::Recursion)
            .map(|v| v.depth)
            .collect();
        assert_eq!(depths, DEPTHS);
        let spps: Vec<u32> = v
            .iter()
            .filter(|v| v.section == Section::Antialiasing)
            .map(|v| v.spp)
            .collect();
        assert_eq!(spps, [256, 1, 4, 16, 64]);
    }

    #[test]
    fn reduced_keeps_the_frame_and_the_aspect() {
        let scene = &suite::generated()[0].scene;
        let small = reduced(scene, 96);
        assert_eq!((small.camera.width, small.camera.height), (96, 64));
        assert_eq!(
            (small.camera.left, small.camera.top),
            (scene.camera.left, scene.camera.top)
        );
        assert_eq!(reduced(&small, 500).camera, small.camera);
    }
}
