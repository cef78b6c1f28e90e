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
        })
        .init_resource::<SceneLoading>()
        .init_resource::<ViewerStatus>()
        .add_message::<LoadScene>()
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
}

/// Asks for a scene file, OBJ, PLY or glTF to be opened.
#[derive(Message, Clone, Debug)]
pub struct LoadScene(pub PathBuf);

/// The load under way, if any.
#[derive(Resource, Default)]
pub struct SceneLoading {
    job: Background<PathBuf, anyhow::Result<Scene>>,
    started: Option<Instant>,
}

impl SceneLoading {
    /// The file being loaded and how long it has taken so far.
    pub fn current(&self) -> Option<(&Path, f32)> {
        Some((
            self.job.key()?.as_path(),
            self.started?.elapsed().as_secs_f32(),
        ))
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

fn start_loading(mut requests: MessageReader<LoadScene>, mut loading: ResMut<SceneLoading>) {
    // Only the newest request matters.
    if let Some(LoadScene(path)) = requests.read().last().cloned() {
        info!("loading {}", path.display());
        let p = path.clone();
        loading
            .job
            .start(path, "tracery-load", move || Scene::load(&p));
        loading.started = Some(Instant::now());
    }
}

fn finish_loading(
    mut loading: ResMut<SceneLoading>,
    mut current: ResMut<CurrentScene>,
    mut status: ResMut<ViewerStatus>,
) {
    let Some((path, result)) = loading.job.poll() else {
        return;
    };
    let took = loading.started.take().map(|t| t.elapsed().as_secs_f32());
    match result.map_err(anyhow::Error::msg).and_then(|r| r) {
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
