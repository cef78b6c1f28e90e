//! The BVH as a resource: rebuilt off the frame when the scene or the BVH settings change,
//! and exactly then.

use std::sync::Arc;
use std::time::Instant;

use bevy::prelude::*;

use super::scene::CurrentScene;
use super::task::Background;
use crate::bvh::{BuildOptions, Bvh};

/// Keeps [`SceneBvh`] in step with [`CurrentScene`] and [`BvhSettings`].
pub struct BvhPlugin {
    /// The settings to build with at start.
    pub options: BuildOptions,
}

impl Plugin for BvhPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(BvhSettings(self.options))
            .init_resource::<SceneBvh>()
            .init_resource::<BvhBuilding>()
            .add_systems(PreUpdate, rebuild_bvh.after(super::scene::SceneSystems));
    }
}

/// How the BVH is built (edited in the inspector).
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct BvhSettings(pub BuildOptions);

/// What a BVH was built from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhKey {
    /// [`CurrentScene::generation`] of the scene.
    pub scene: u64,
    /// The build settings.
    pub options: BuildOptions,
}

/// The BVH of the current scene (or of the previous one, or with the previous settings, while
/// the new one builds: `key` says which).
#[derive(Resource, Default)]
pub struct SceneBvh {
    /// The tree, once one is built.
    pub bvh: Option<Arc<Bvh>>,
    /// What it was built from.
    pub key: Option<BvhKey>,
    /// Builds installed since start.
    pub builds: u64,
}

impl SceneBvh {
    /// The tree if it belongs to the scene of generation `scene`.
    pub fn for_scene(&self, scene: u64) -> Option<&Arc<Bvh>> {
        match self.key {
            Some(k) if k.scene == scene => self.bvh.as_ref(),
            _ => None,
        }
    }
}

/// The build under way, if any.
#[derive(Resource, Default)]
pub struct BvhBuilding {
    job: Background<BvhKey, Bvh>,
    started: Option<Instant>,
    /// A build that failed (not retried until the key changes).
    failed: Option<BvhKey>,
}

impl BvhBuilding {
    /// Seconds the build under way has taken so far.
    pub fn elapsed(&self) -> Option<f32> {
        self.job
            .is_running()
            .then(|| self.started.map(|t| t.elapsed().as_secs_f32()))
            .flatten()
    }
}

fn rebuild_bvh(
    scene: Res<CurrentScene>,
    settings: Res<BvhSettings>,
    mut bvh: ResMut<SceneBvh>,
    mut building: ResMut<BvhBuilding>,
) {
    let wanted = BvhKey {
        scene: scene.generation,
        options: settings.0,
    };
    if let Some((key, result)) = building.job.poll() {
        match result {
            Ok(tree) if key == wanted => {
                info!(
                    "BVH built in {:.1} ms: {} nodes, {} levels, SAH cost {:.2}",
                    tree.stats.build_ms, tree.stats.nodes, tree.stats.levels, tree.stats.sah_cost
                );
                bvh.bvh = Some(Arc::new(tree));
                bvh.key = Some(key);
                bvh.builds += 1;
            }
            Ok(_) => {} // superseded while it built
            Err(e) => {
                error!("BVH build failed: {e}");
                building.failed = Some(key);
            }
        }
    }
    if bvh.key == Some(wanted)
        || building.job.key() == Some(&wanted)
        || building.failed == Some(wanted)
    {
        return;
    }
    let triangles = scene.scene.clone();
    let options = settings.0;
    building.job.start(wanted, "tracery-bvh", move || {
        Bvh::build(&triangles.mesh.triangles, &options)
    });
    building.started = Some(Instant::now());
}
