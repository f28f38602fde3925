//! Where a run's views and scene come from, shared by the subcommands, the
//! studies and the studio: a camera file or an orbit framed around the
//! scene, and a scene loaded with its path in the error.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use gast_core::camera::{OrbitOptions, crop_view, framed_orbit, framing_subject, orbit_cameras};
use gast_core::{Camera, Gaussians};

/// Where the views come from: a camera file, or an orbit generated around the scene.
#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// Camera file or folder (COLMAP sparse/0, poses_bounds.npy, cameras.json, transforms.json).
    /// Without it, the cameras beside the scene (its folder's, as `gast fit`
    /// writes them, or an INRIA model folder's cameras.json), else views
    /// generated on an orbit around the scene.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Generate orbit views even when the scene's folder holds cameras.
    #[arg(long, conflicts_with = "cameras")]
    pub orbit: bool,
    /// Number of generated orbit views, 1 to 3,600 (ignored when cameras are read).
    #[arg(long, default_value_t = 8, value_parser = view_count::<usize>())]
    pub views: usize,
    /// Longer side of the rendered images in pixels, 16 to 8,192 (camera intrinsics are rescaled).
    #[arg(long, default_value_t = 512, value_parser = image_side())]
    pub size: u32,
    /// Vertical field of view of generated views, in degrees (1 to 170).
    #[arg(long, default_value_t = 50.0, value_parser = fov_degrees)]
    pub fov: f32,
    /// How generated views frame the scene: `full` is the plain orbit that
    /// fits the object's bounding sphere (square images); `object` fits each
    /// view's intrinsics and aspect ratio to the object so it spans 90% of the
    /// longer side (`gast stylize` defaults to `object`).
    #[arg(long, value_enum, default_value_t = Framing::Full)]
    pub framing: Framing,
    /// With --cameras: crop each view to the region the scene's object covers.
    #[arg(long)]
    pub crop: bool,
}

/// The number of views a command generates: 1 to 3,600 (`--views`, `--turntable`).
pub const VIEW_COUNTS: std::ops::RangeInclusive<u32> = 1..=3600;

/// A whole-number flag of type `T` refused outside `range` (one of the
/// core's ranges, of u32 or usize): every ranged flag of the command line is
/// made here or by [`within`] ("N is not in A..=B").
pub(crate) fn within_as<T, R>(range: std::ops::RangeInclusive<R>) -> clap::builder::RangedU64ValueParser<T>
where
    R: Copy + TryInto<u64>,
    T: TryFrom<u64> + Clone + Send + Sync + 'static,
    <T as TryFrom<u64>>::Error: std::error::Error + Send + Sync + 'static,
{
    let bound = |v: R| v.try_into().unwrap_or(u64::MAX);
    clap::builder::RangedU64ValueParser::new().range(bound(*range.start())..=bound(*range.end()))
}

/// [`within_as`] for a flag of the range's own type.
pub(crate) fn within<T>(range: std::ops::RangeInclusive<T>) -> clap::builder::RangedU64ValueParser<T>
where
    T: Copy + TryInto<u64> + TryFrom<u64> + Send + Sync + 'static,
    <T as TryFrom<u64>>::Error: std::error::Error + Send + Sync + 'static,
{
    within_as(range)
}

/// A `--views` or `--turntable` count, refused outside [`VIEW_COUNTS`].
pub(crate) fn view_count<T>() -> clap::builder::RangedU64ValueParser<T>
where
    T: TryFrom<u64> + Clone + Send + Sync + 'static,
    <T as TryFrom<u64>>::Error: std::error::Error + Send + Sync + 'static,
{
    within_as(VIEW_COUNTS)
}

/// An image's longer side in pixels (`--size`, `--resolution`, `--sizes`),
/// refused outside [`gast_core::camera::IMAGE_SIDES`].
pub(crate) fn image_side() -> clap::builder::RangedU64ValueParser<u32> {
    within(gast_core::camera::IMAGE_SIDES)
}

/// A count that must be at least one (`--reps`, `--draws`, `--frames`,
/// `--steps`, …): zero would time or draw nothing and print a median of nothing.
pub(crate) fn at_least_one<T>(s: &str) -> Result<T, String>
where
    T: std::str::FromStr + From<u8> + PartialOrd,
    T::Err: std::fmt::Display,
{
    let v: T = s.parse().map_err(|e| format!("expected a whole number of at least 1, found {s:?}: {e}"))?;
    if v >= T::from(1) { Ok(v) } else { Err(format!("expected at least 1, found {s}")) }
}

/// A colour channel from 0 to 1 (`--background r,g,b`).
pub(crate) fn unit_channel(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("expected a number from 0 to 1, found {s:?}: {e}"))?;
    if (0.0..=1.0).contains(&v) { Ok(v) } else { Err(format!("expected a number from 0 to 1, found {v}")) }
}

/// `--fov`: a vertical field of view in degrees, 1 to 170 (a pinhole camera
/// has none at 0 and wraps past 180).
pub(crate) fn fov_degrees(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("expected degrees (a number), found {s:?}: {e}"))?;
    if (1.0..=170.0).contains(&v) { Ok(v) } else { Err(format!("expected 1 to 170 degrees, found {v}")) }
}

/// How generated views frame the scene (see [`ViewArgs::framing`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Framing {
    /// Each view fitted to the object, which spans 90% of its longer side (`camera::framed_orbit`).
    #[default]
    Object,
    /// The plain orbit around the scene's bounding sphere, square images (`camera::orbit_cameras`).
    Full,
}

/// Loads a scene with its path in the error, printing the readers' warnings.
pub fn load_scene(path: &Path) -> anyhow::Result<Gaussians> {
    let (scene, warnings) = gast_core::scene::load_with_warnings(path)
        .with_context(|| format!("could not load the scene {}", path.display()))?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Refuses `out`, the folder the option `flag` names, when it holds the
/// photos of the `cameras` read from `camera_source` (a COLMAP, NeRF or
/// LLFF dataset, [`gast_core::fit::photo_folders`]): a view's `image000.png`
/// would replace the photo of that name, and an LLFF folder pairs its images
/// with the poses by count. A folder that does not exist yet holds none.
pub fn refuse_photo_folder(
    out: &Path,
    flag: &str,
    camera_source: Option<&Path>,
    cameras: &[Camera],
) -> anyhow::Result<()> {
    if let Some(source) = camera_source {
        let photos = gast_core::fit::photo_folders(source, cameras.iter().map(|c| c.name.as_str()));
        refuse_among_photos(out, flag, &photos, source)?;
    }
    refuse_dataset_photo_folder(out, flag)
}

/// Refuses `out` when the folder above it is a dataset whose cameras'
/// photos are in `out` (lego's `train`, fern's `images_4`, a COLMAP
/// `images`), whatever cameras the command uses: an orbit render or a
/// turntable there mixed its files with the photos, and an LLFF folder
/// pairs its images with the poses by count.
pub fn refuse_dataset_photo_folder(out: &Path, flag: &str) -> anyhow::Result<()> {
    let Ok(canonical) = std::fs::canonicalize(out) else { return Ok(()) };
    let Some(dataset) = canonical.parent() else { return Ok(()) };
    let Ok(set) = gast_core::camera::load(dataset) else { return Ok(()) };
    let photos = gast_core::fit::photo_folders(dataset, set.cameras.iter().map(|c| c.name.as_str()));
    refuse_among_photos(out, flag, &photos, dataset)
}

/// Refuses `out`, the folder the option `flag` names, when it is one of
/// `photos` (canonical folders of the dataset `source`'s photos, as
/// [`gast_core::fit::photo_folders`] finds them). A folder that does not
/// exist yet is none of them.
pub fn refuse_among_photos(out: &Path, flag: &str, photos: &[PathBuf], source: &Path) -> anyhow::Result<()> {
    let Ok(out_canonical) = std::fs::canonicalize(out) else { return Ok(()) };
    anyhow::ensure!(
        !photos.contains(&out_canonical),
        "{flag} {}: expected a folder apart from the photos, found a folder of the photos of {} (the outputs \
         would replace or mix with them; choose another folder)",
        out.display(),
        source.display()
    );
    Ok(())
}

/// Writes `cameras`, read from `source`, as `cameras.json` beside the
/// written scene `scene` (the INRIA trainer's layout), so that the studio,
/// `gast stylize` and `gast render` start from them
/// ([`gast_core::camera::beside_scene`]) rather than from an orbit, which sees
/// a forward-facing capture from outside. A folder that holds other cameras
/// keeps them: the dataset's own (the scene written into it), or a
/// `cameras.json` of other images, left as it is with a warning; one of the
/// same images is replaced. Returns what to tell the user, a line each.
pub fn write_cameras_beside(scene: &Path, source: &Path, cameras: &[Camera]) -> anyhow::Result<Vec<String>> {
    let dir = scene.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let path = dir.join("cameras.json");
    let same = |set: &gast_core::camera::CameraSet| {
        set.cameras.len() == cameras.len() && set.cameras.iter().zip(cameras).all(|(a, b)| a.name == b.name)
    };
    match gast_core::camera::beside_scene(scene) {
        None => {}
        // The same images' cameras: a rerun replaces its own cameras.json;
        // the dataset's own files (the scene written into it) need none.
        Some(Ok((set, _))) if same(&set) && !path.is_file() => return Ok(Vec::new()),
        Some(Ok((set, _))) if same(&set) => {}
        Some(Ok((set, found))) => {
            return Ok(vec![format!(
                "warning: {} already holds the cameras of other images ({} of them, not the {} written now); they are \
                 left as they are, and the studio and `gast stylize` will take them for this scene unless given \
                 --cameras {}",
                found.display(),
                set.cameras.len(),
                cameras.len(),
                source.display()
            )]);
        }
        Some(Err(e)) => {
            return Ok(vec![format!(
                "warning: cameras.json is not written: the camera file beside the scene is kept: {e}"
            )]);
        }
    }
    let off_centre = gast_core::camera::write_inria(&path, cameras)
        .with_context(|| format!("could not write the cameras to {}", path.display()))?;
    let mut said = vec![format!(
        "wrote {} ({} cameras): the studio, `gast stylize` and `gast render` use them for this scene",
        path.display(),
        cameras.len()
    )];
    if off_centre > 0 {
        said.push(format!(
            "note: {off_centre} of the cameras have their principal point off the image centre: cameras.json \
             keeps it in cx/cy keys, which gast reads and other readers of the format ignore (they take the centre)"
        ));
    }
    Ok(said)
}

/// The camera file a command reads: `cameras` (`--cameras`) when given,
/// else, unless `orbit` (`--orbit`), the folder beside `scene` that holds its
/// training cameras ([`gast_core::camera::beside_scene`], said on stderr),
/// else none (generated views). A camera file beside the scene that cannot be
/// read is an error naming it, not a silent orbit; cameras beside it that
/// mostly do not see `gaussians` ([`gast_core::session::plan::foreign_cameras`])
/// are left out with a warning.
pub fn camera_source(
    scene: &Path,
    gaussians: &Gaussians,
    cameras: Option<&Path>,
    orbit: bool,
) -> anyhow::Result<Option<PathBuf>> {
    if cameras.is_some() || orbit {
        return Ok(cameras.map(Path::to_path_buf));
    }
    match gast_core::camera::beside_scene(scene) {
        None => Ok(None),
        Some(Ok((set, dir))) => {
            if let Some(why) = gast_core::session::plan::foreign_cameras(gaussians, &set.cameras) {
                eprintln!(
                    "warning: the cameras found beside the scene in {} are not used: {why}; generating orbit views \
                     instead (--cameras {} takes them anyway)",
                    dir.display(),
                    dir.display()
                );
                return Ok(None);
            }
            eprintln!(
                "cameras: the {} views found beside the scene in {} (--orbit generates views instead)",
                set.cameras.len(),
                dir.display()
            );
            Ok(Some(dir))
        }
        Some(Err(e)) => Err(anyhow::Error::new(e).context(format!(
            "could not read the cameras beside the scene {} (give --cameras, or --orbit for generated views)",
            scene.display()
        ))),
    }
}

/// The views of `args` for `scene`: the camera file (cropped to the object with
/// `--crop`) rescaled to `--size`, or an orbit framed as `--framing` says.
pub fn views_for(scene: &Gaussians, args: &ViewArgs) -> anyhow::Result<Vec<Camera>> {
    let size = args.size.max(1);
    if let Some(path) = &args.cameras {
        let set =
            gast_core::camera::load(path).with_context(|| format!("could not load the cameras {}", path.display()))?;
        for w in &set.warnings {
            eprintln!("warning: {w}");
        }
        let subject = if args.crop { framing_subject(scene) } else { Vec::new() };
        Ok(set
            .cameras
            .iter()
            .map(|c| if args.crop { crop_view(c, &subject) } else { c.clone() }.with_longer_side(size))
            .collect())
    } else {
        let opts = OrbitOptions {
            count: args.views.max(1),
            width: size,
            height: size,
            fov_y_degrees: args.fov,
            ..OrbitOptions::default()
        };
        Ok(match args.framing {
            Framing::Object => framed_orbit(scene, &opts),
            Framing::Full => orbit_cameras(&scene.means, &opts),
        })
    }
}
