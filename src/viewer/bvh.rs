//! The BVH as a resource: rebuilt off the frame when the scene or the BVH settings change,
//! and exactly then. Another instant of an animation (the same file, its triangles moved)
//! refits the current tree instead, unless refitting has cost it too much quality
//! ([`Bvh::refit_or_rebuild`]).

use std::sync::Arc;
use std::time::Instant;

use bevy::prelude::*;

use super::scene::CurrentScene;
use super::task::Background;
use crate::bvh::{BuildOptions, Bvh, Update};

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
    /// Builds installed since start (refits included).
    pub builds: u64,
    /// Of those, the refits.
    pub refits: u64,
    /// The SAH cost of the tree when it was last built (refits are measured against it).
    pub built_cost: f64,
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
    job: Background<BvhKey, (Bvh, Option<Update>)>,
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
            Ok((tree, update)) if key == wanted => {
                match &update {
                    Some(Update::Refitted(r)) => {
                        info!(
                            "BVH refitted in {:.1} ms: SAH cost {:.2} ({:.2} when built)",
                            r.ms, r.sah_cost, bvh.built_cost
                        );
                        bvh.refits += 1;
                    }
                    rebuilt => {
                        if let Some(Update::Rebuilt(why)) = rebuilt {
                            info!("BVH built again: {why}");
                        }
                        info!(
                            "BVH built in {:.1} ms: {} nodes, {} levels, SAH cost {:.2}",
                            tree.stats.build_ms,
                            tree.stats.nodes,
                            tree.stats.levels,
                            tree.stats.sah_cost
                        );
                        bvh.built_cost = tree.stats.sah_cost;
                    }
                }
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
    // Another instant of the same file: the current tree, refitted (a copy: the pictures
    // under way keep tracing the old one).
    let previous = bvh
        .bvh
        .clone()
        .filter(|b| !scene.reframe && b.options == options);
    let built_cost = bvh.built_cost;
    building
        .job
        .start(wanted, "tracery-bvh", move || match previous {
            Some(tree) => {
                let mut tree = (*tree).clone();
                let update = tree.refit_or_rebuild(&triangles.mesh.triangles, built_cost);
                (tree, Some(update))
            }
            None => (Bvh::build(&triangles.mesh.triangles, &options), None),
        });
    building.started = Some(Instant::now());
}
