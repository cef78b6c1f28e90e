//! The BVH as a resource: rebuilt off the frame when the scene or the BVH settings change,
//! and exactly then. Another instant of an animation (the same file, its triangles moved)
//! refits the current tree instead, unless refitting has cost it too much quality
//! ([`Bvh::refit_or_rebuild`]).

use std::sync::Arc;
use std::time::Instant;

use bevy::prelude::*;

use super::scene::CurrentScene;
use super::task::Background;
use crate::bvh::{Accel, BuildOptions, Bvh, Tree, TwoLevel, Update};

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
            .add_systems(
                PreUpdate,
                rebuild_bvh
                    .after(super::scene::SceneSystems)
                    .after(super::objects::ObjectSystems),
            );
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
    /// The tree of the scene's own triangles (those placed once), once one is built.
    pub bvh: Option<Arc<Bvh>>,
    /// For a scene that places meshes many times, the two levels rays are traced through
    /// (with `bvh` as one of their meshes' trees).
    pub placed: Option<Arc<TwoLevel>>,
    /// Whether the scene the trees were built for places meshes many times (then rays are
    /// traced only through `placed`, never through `bvh` alone).
    pub needs_placed: bool,
    /// What it was built from.
    pub key: Option<BvhKey>,
    /// Builds installed since start (refits included).
    pub builds: u64,
    /// Of those, the refits.
    pub refits: u64,
    /// Top levels built alone, every mesh's tree kept, after objects moved.
    pub top_builds: u64,
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

    /// What the rays of the scene of generation `scene` are traced through: the two levels
    /// of a scene that places meshes many times, else the one tree.
    pub fn tracing(&self, scene: u64) -> Option<Tree<'_>> {
        let own = self.for_scene(scene)?;
        match (&self.placed, self.needs_placed) {
            (Some(t), _) => Some(Tree::TwoLevel(t)),
            (None, false) => Some(Tree::Flat(own)),
            // Its placements could not be placed (said in the log): nothing to trace.
            (None, true) => None,
        }
    }
}

/// What a build gives: the tree of the scene's own triangles, how it was made when refitted,
/// and the two levels of a scene that places meshes many times.
type Built = (Arc<Bvh>, Option<Update>, Option<Arc<TwoLevel>>);

/// The build under way, if any.
#[derive(Resource, Default)]
pub struct BvhBuilding {
    job: Background<BvhKey, Built>,
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
            Ok((tree, update, placed)) if key == wanted => {
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
                if let Some(t) = &placed {
                    info!(
                        "{} placements of {} meshes: top level built in {:.2} ms",
                        t.instance_count(),
                        t.meshes.len(),
                        t.build_ms
                    );
                }
                bvh.bvh = Some(tree);
                bvh.placed = placed;
                bvh.needs_placed = !scene.scene.instances.is_empty();
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
    // Objects moved: the same meshes, so the same trees under a new top level, built here
    // (a thousand placements take a fraction of a millisecond).
    if let (Some(from), Some(key), Some(two)) = (scene.moved_from, bvh.key, bvh.placed.clone())
        && key.scene == from
        && key.options == settings.0
        && building.job.key().is_none()
        && !scene.lifted
    {
        let own = !scene.scene.mesh.triangles.is_empty();
        match Accel::place(&scene.scene, two.meshes.clone(), own) {
            Ok(Accel::TwoLevel(t)) => {
                info!(
                    "top level of {} placements built again in {:.2} ms",
                    t.instance_count(),
                    t.build_ms
                );
                bvh.placed = Some(Arc::new(t));
                bvh.key = Some(wanted);
                bvh.top_builds += 1;
                return;
            }
            Ok(Accel::Flat(_)) => {}
            Err(e) => error!("{}: {e}", scene.scene.name),
        }
    }
    let triangles = scene.scene.clone();
    let options = settings.0;
    // Objects lifted out of the scene's own triangles: the meshes placed before keep their
    // trees (the lifted ones come after them), the own triangles' and the new meshes' are
    // built.
    let kept: Vec<Arc<Bvh>> = match (scene.moved_from, bvh.key, &bvh.placed) {
        (Some(from), Some(key), Some(two))
            if scene.lifted && key.scene == from && key.options == options =>
        {
            two.meshes.iter().skip(1).cloned().collect()
        }
        _ => Vec::new(),
    };
    // Another instant of the same file: the current tree, refitted (a copy: the pictures
    // under way keep tracing the old one).
    let previous = bvh
        .bvh
        .clone()
        .filter(|b| !scene.reframe && !scene.lifted && b.options == options);
    let built_cost = bvh.built_cost;
    building.job.start(wanted, "tracery-bvh", move || {
        let (own, update) = match previous {
            Some(tree) => {
                let mut tree = (*tree).clone();
                let update = tree.refit_or_rebuild(&triangles.mesh.triangles, built_cost);
                (Arc::new(tree), Some(update))
            }
            None => (
                Arc::new(Bvh::build(&triangles.mesh.triangles, &options)),
                None,
            ),
        };
        (
            own.clone(),
            update,
            placed_trees(&triangles, own, kept, &options),
        )
    });
    building.started = Some(Instant::now());
}

/// The two levels of a scene that places meshes many times (`None` for one that does not),
/// `own` the tree of its own triangles, `kept` the trees of its first meshes where they are
/// built already; a placement the top level refuses is logged and the scene traced without
/// its placements.
fn placed_trees(
    scene: &crate::scene::Scene,
    own: Arc<Bvh>,
    kept: Vec<Arc<Bvh>>,
    options: &BuildOptions,
) -> Option<Arc<TwoLevel>> {
    if scene.instances.is_empty() {
        return None;
    }
    let has_own = !scene.mesh.triangles.is_empty();
    let mut meshes = Vec::with_capacity(scene.instances.meshes.len() + 1);
    if has_own {
        meshes.push(own);
    }
    let reused = kept.len().min(scene.instances.meshes.len());
    meshes.extend(kept.into_iter().take(reused));
    meshes.extend(
        scene.instances.meshes[reused..]
            .iter()
            .map(|m| Arc::new(Bvh::build(&m.triangles, options))),
    );
    match Accel::place(scene, meshes, has_own) {
        Ok(Accel::TwoLevel(t)) => Some(Arc::new(t)),
        Ok(Accel::Flat(_)) => None,
        Err(e) => {
            error!("{}: {e}", scene.name);
            None
        }
    }
}
