//! The loaded scene as a resource: files load off the frame, a file that fails leaves the
//! current scene in place and shows its error.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use bevy::prelude::*;

use super::task::Background;
use crate::scene::{Format, Scene};

/// Loads scenes on request ([`LoadScene`]) and keeps the current one ([`CurrentScene`]).
pub struct ScenePlugin {
    /// The scene to open at start (`None`: the built-in Cornell box).
    pub initial: Option<PathBuf>,
}

impl Plugin for ScenePlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(CurrentScene {
            scene: Arc::new(Scene::cornell_box()),
            source: None,
            generation: 0,
            time: None,
            reframe: true,
            moved_from: None,
            lifted: false,
        })
        .init_resource::<SceneLoading>()
        .init_resource::<ViewerStatus>()
        .add_message::<LoadScene>()
        .add_message::<ShowInstant>()
        .add_systems(
            PreUpdate,
            (start_loading, finish_loading).chain().in_set(SceneSystems),
        );
        if let Some(path) = &self.initial {
            app.world_mut().write_message(LoadScene(path.clone()));
        }
    }
}

/// The scene systems (loading), which everything derived from the scene runs after.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct SceneSystems;

/// The scene being shown, shared with the background jobs that build its BVH.
#[derive(Resource)]
pub struct CurrentScene {
    /// The scene.
    pub scene: Arc<Scene>,
    /// The file it came from (`None`: built in).
    pub source: Option<PathBuf>,
    /// Counts the scenes installed; anything derived from a scene remembers this.
    pub generation: u64,
    /// The instant of the file's animations the scene shows (`None`: as the file places its
    /// nodes).
    pub time: Option<f64>,
    /// Whether the last scene installed was a new file (the camera goes to its view), not
    /// another instant of the same one (the camera stays).
    pub reframe: bool,
    /// When the scene is the one of this generation with objects moved
    /// ([`super::objects`]): that generation (the meshes and their trees are the same).
    pub moved_from: Option<u64>,
    /// Whether objects were lifted out of the scene's own triangles in that move (then the
    /// own triangles' tree and the lifted meshes' are built; the other meshes' trees are
    /// kept).
    pub lifted: bool,
}

/// Asks for a scene file, OBJ, PLY or glTF to be opened.
#[derive(Message, Clone, Debug)]
pub struct LoadScene(pub PathBuf);

/// Asks for the current file at another instant of its animations (seconds): loaded off the
/// frame like a file, installed as the current scene without moving the camera.
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct ShowInstant(pub f64);

/// The load under way, if any: the file, and the instant asked for.
#[derive(Resource, Default)]
pub struct SceneLoading {
    job: Background<(PathBuf, Option<f64>), anyhow::Result<Scene>>,
    started: Option<Instant>,
}

impl SceneLoading {
    /// The file being opened and how long it has taken so far (not another instant of the
    /// file shown: those load one after another while an animation plays).
    pub fn current(&self) -> Option<(&Path, f32)> {
        let (path, time) = self.job.key()?;
        time.is_none()
            .then(|| Some((path.as_path(), self.started?.elapsed().as_secs_f32())))?
    }

    /// Whether a load (of a file, or of an instant) is under way.
    pub fn busy(&self) -> bool {
        self.job.is_running()
    }
}

/// What the viewer tells the user: the last error, and notices (saved files, warnings).
#[derive(Resource, Default, Debug)]
pub struct ViewerStatus {
    /// The last failure, shown until the next successful load.
    pub error: Option<String>,
    /// The last notice.
    pub notice: Option<String>,
}

fn start_loading(
    mut requests: MessageReader<LoadScene>,
    mut instants: MessageReader<ShowInstant>,
    current: Res<CurrentScene>,
    mut loading: ResMut<SceneLoading>,
) {
    // Only the newest request matters; a new file before another instant of the old one.
    let instant = instants.read().last().copied();
    let (path, time) = match (requests.read().last().cloned(), instant, &current.source) {
        (Some(LoadScene(path)), ..) => {
            info!("loading {}", path.display());
            (path, None)
        }
        (None, Some(ShowInstant(t)), Some(source)) => (source.clone(), Some(t)),
        _ => return,
    };
    let p = path.clone();
    loading.job.start((path, time), "tracery-load", move || {
        Scene::load_at(&p, time)
    });
    loading.started = Some(Instant::now());
}

fn finish_loading(
    mut loading: ResMut<SceneLoading>,
    mut current: ResMut<CurrentScene>,
    mut status: ResMut<ViewerStatus>,
) {
    let Some(((path, time), result)) = loading.job.poll() else {
        return;
    };
    let took = loading.started.take().map(|t| t.elapsed().as_secs_f32());
    match result.map_err(anyhow::Error::msg).and_then(|r| r) {
        // Another instant of the file shown: the camera stays. (Its warnings are the file's,
        // less the one that says the animations are not played.)
        Ok(scene) if time.is_some() && current.source.as_ref() == Some(&path) => {
            status.error = None;
            status.notice = (!scene.warnings.is_empty()).then(|| scene.warnings.join("\n"));
            current.scene = Arc::new(scene);
            current.generation += 1;
            current.time = time;
            current.reframe = false;
            current.moved_from = None;
            current.lifted = false;
        }
        Ok(scene) => {
            info!(
                "loaded {} ({} triangles) in {:.2} s",
                path.display(),
                scene.triangle_count(),
                took.unwrap_or(0.0)
            );
            status.error = None;
            status.notice = (!scene.warnings.is_empty()).then(|| scene.warnings.join("\n"));
            current.scene = Arc::new(scene);
            current.source = Some(path);
            current.generation += 1;
            current.time = time;
            current.reframe = true;
            current.moved_from = None;
            current.lifted = false;
        }
        Err(e) => {
            let msg = format!("{e:#}");
            error!("{msg}");
            status.error = Some(msg);
        }
    }
}

/// What the inspector's list offers: every file in `folder` (`assets/scenes`) the viewer can
/// open (scene files, OBJ, PLY, glTF), sorted.
pub fn scene_files(folder: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(folder)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| Format::of(p).is_some())
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}
