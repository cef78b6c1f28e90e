//! BVH gizmos: the boxes of one level coloured by level (with the boxes that overlap a
//! sibling standing out in the overlap view), and the leaves (all, or one with its triangles
//! outlined). Each drawing is its own gizmo group with a key and an inspector toggle.
//!
//! The tree drawn is the scene's; in a scene that places meshes many times, the top level
//! over the placements, or, while an object is picked ([`super::objects`]), that object's
//! own mesh tree where the object stands.

use std::sync::Arc;

use bevy::prelude::*;

use glam::Affine3A;

use super::UiFocus;
use super::bvh::{BvhKey, SceneBvh};
use super::objects::{SceneObject, Selection};
use super::scene::CurrentScene;
use super::trace::{RenderMode, ViewSettings};
use crate::bvh::{Bvh, BvhNode, TwoLevel};
use crate::scene::Place;

/// Draws the BVH level and leaf gizmos.
pub struct BvhGizmoPlugin;

impl Plugin for BvhGizmoPlugin {
    fn build(&self, app: &mut App) {
        app.init_gizmo_group::<BvhLevelGizmos>()
            .init_gizmo_group::<LeafGizmos>()
            .init_resource::<LeafView>()
            .init_resource::<BvhIndex>()
            .add_systems(Startup, default_off)
            .add_systems(Update, (index_bvh, keys, draw_level, draw_leaves).chain());
    }
}

/// The boxes of one BVH level (key B).
#[derive(Default, Reflect, GizmoConfigGroup)]
pub struct BvhLevelGizmos;

/// The BVH leaves (key L).
#[derive(Default, Reflect, GizmoConfigGroup)]
pub struct LeafGizmos;

/// Which leaves to draw.
#[derive(Resource, Debug, Clone, PartialEq)]
pub struct LeafView {
    /// Draw every leaf (else only leaf `index` with its triangles).
    pub all: bool,
    /// The leaf drawn alone, counted in the order of [`BvhIndex::leaves`].
    pub index: u32,
    /// Most boxes drawn at once (the rest are left out, and the inspector says so).
    pub max_boxes: usize,
}

impl Default for LeafView {
    fn default() -> Self {
        Self {
            all: false,
            index: 0,
            max_boxes: 20_000,
        }
    }
}

/// A tree the gizmos draw.
#[derive(Clone, Debug)]
pub enum Indexed {
    /// A mesh's tree (the scene's own, or a picked object's mesh's).
    Tree(Arc<Bvh>),
    /// The top level over a scene's placements.
    Top(Arc<TwoLevel>),
}

impl Indexed {
    fn nodes(&self) -> &[BvhNode] {
        match self {
            Indexed::Tree(b) => &b.nodes,
            Indexed::Top(t) => t.top_nodes(),
        }
    }

    fn same(&self, other: &Indexed) -> bool {
        match (self, other) {
            (Indexed::Tree(a), Indexed::Tree(b)) => Arc::ptr_eq(a, b),
            (Indexed::Top(a), Indexed::Top(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

/// The drawn tree's nodes sorted by level, and its leaves, for drawing and the sliders.
#[derive(Resource, Default)]
pub struct BvhIndex {
    indexed: Option<Indexed>,
    /// Where the tree's boxes are drawn: a picked object's placement, else the identity.
    pub to_world: Affine3A,
    /// What the tree is, for the inspector.
    pub what: String,
    /// The BVH build (and count of top levels built alone) the index was made from.
    pub made_for: Option<(BvhKey, u64)>,
    /// Node indices at each depth.
    pub levels: Vec<Vec<u32>>,
    /// Leaf node indices, in node order.
    pub leaves: Vec<u32>,
    /// For each node, whether its box overlaps its sibling's.
    pub overlaps_sibling: Vec<bool>,
}

impl BvhIndex {
    /// Indexes `bvh`, drawn as it is.
    pub fn new(bvh: Arc<Bvh>) -> Self {
        Self::of(
            Indexed::Tree(bvh),
            Affine3A::IDENTITY,
            "the scene's BVH".into(),
        )
    }

    /// Indexes `indexed`, drawn through `to_world`.
    pub fn of(indexed: Indexed, to_world: Affine3A, what: String) -> Self {
        let nodes = indexed.nodes();
        let mut levels: Vec<Vec<u32>> = Vec::new();
        let mut leaves = Vec::new();
        let mut depth = vec![0u32; nodes.len()];
        let mut overlaps = vec![false; nodes.len()];
        let empty = match &indexed {
            Indexed::Tree(b) => b.is_empty(),
            Indexed::Top(t) => t.bounds().is_empty(),
        };
        if !empty {
            for (i, n) in nodes.iter().enumerate() {
                if i == 1 {
                    continue; // the unused slot
                }
                let d = depth[i] as usize;
                if levels.len() <= d {
                    levels.resize(d + 1, Vec::new());
                }
                levels[d].push(i as u32);
                if n.is_leaf() {
                    leaves.push(i as u32);
                } else {
                    let (a, b) = (n.first as usize, n.first as usize + 1);
                    depth[a] = depth[i] + 1;
                    depth[b] = depth[i] + 1;
                    // Overlap with volume: shared faces do not count.
                    let (ba, bb) = (nodes[a].aabb(), nodes[b].aabb());
                    let o = ba.max.min(bb.max).cmpgt(ba.min.max(bb.min)).all();
                    overlaps[a] = o;
                    overlaps[b] = o;
                }
            }
        }
        Self {
            indexed: Some(indexed),
            to_world,
            what,
            made_for: None,
            levels,
            leaves,
            overlaps_sibling: overlaps,
        }
    }

    /// The indexed mesh tree (`None` for the top level).
    pub fn bvh(&self) -> Option<&Arc<Bvh>> {
        match &self.indexed {
            Some(Indexed::Tree(b)) => Some(b),
            _ => None,
        }
    }

    /// Node `i` of the indexed tree.
    fn node(&self, i: u32) -> Option<&BvhNode> {
        self.indexed.as_ref()?.nodes().get(i as usize)
    }
}

/// The colour of BVH level `level`: hues step around the wheel.
pub fn level_color(level: u32) -> Color {
    Color::hsl((level as f32 * 47.0) % 360.0, 0.85, 0.6)
}

fn default_off(mut store: ResMut<GizmoConfigStore>) {
    store.config_mut::<BvhLevelGizmos>().0.enabled = false;
    store.config_mut::<LeafGizmos>().0.enabled = false;
}

/// Indexes each new tree (the scene's, its top level, or the picked object's mesh's), and
/// brings the level and leaf shown into its range (a `--leaf` or `--level` past it, or a
/// rebuild with fewer leaves, would otherwise draw nothing), saying so.
fn index_bvh(
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
    mut index: ResMut<BvhIndex>,
    mut settings: ResMut<ViewSettings>,
    mut leaves: ResMut<LeafView>,
    (selection, objects): (Res<Selection>, Query<&SceneObject>),
) {
    let Some(tree) = bvh.for_scene(current.generation) else {
        return;
    };
    // A picked object placed by a placement: its mesh's own tree, where it stands.
    let picked = selection.0.and_then(|e| objects.get(e).ok()).and_then(|o| {
        let object = current.scene.objects.get(o.object)?;
        match object.place {
            Place::Placed(p) => Some((object, current.scene.instances.placements().get(p)?)),
            Place::Own { .. } => None,
        }
    });
    let (want, to_world, what) = match (&bvh.placed, picked) {
        (Some(two), Some((object, p))) => {
            let shift = !current.scene.mesh.triangles.is_empty() as usize;
            let Some(mesh) = two.meshes.get(p.mesh as usize + shift).cloned() else {
                return;
            };
            (
                Indexed::Tree(mesh),
                p.to_world,
                format!("the BVH of {} (mesh {})", object.name, p.mesh),
            )
        }
        (Some(two), None) => (
            Indexed::Top(two.clone()),
            Affine3A::IDENTITY,
            "the top level over the placements".into(),
        ),
        (None, _) => (
            Indexed::Tree(tree.clone()),
            Affine3A::IDENTITY,
            "the scene's BVH".into(),
        ),
    };
    let made_for = bvh.key.map(|k| (k, bvh.top_builds));
    if index.indexed.as_ref().is_some_and(|i| i.same(&want)) && index.to_world == to_world {
        index.made_for = made_for;
        return;
    }
    *index = BvhIndex::of(want, to_world, what);
    index.made_for = made_for;
    if let Some(last) = index.leaves.len().checked_sub(1).map(|l| l as u32)
        && leaves.index > last
    {
        eprintln!(
            "warning: leaf {} asked for, the tree has {} leaves: leaf {last} shown",
            leaves.index,
            last + 1
        );
        leaves.index = last;
    }
    if let Some(depth) = index.levels.len().checked_sub(1).map(|d| d as u32)
        && settings.level > depth
    {
        eprintln!(
            "warning: level {} asked for, the tree's deepest is {depth}: level {depth} shown",
            settings.level
        );
        settings.level = depth;
    }
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    focus: Res<UiFocus>,
    index: Res<BvhIndex>,
    mut store: ResMut<GizmoConfigStore>,
    mut settings: ResMut<ViewSettings>,
    mut leaves: ResMut<LeafView>,
) {
    if focus.keyboard {
        return;
    }
    if input.just_pressed(KeyCode::KeyB) {
        let c = &mut store.config_mut::<BvhLevelGizmos>().0.enabled;
        *c = !*c;
    }
    if input.just_pressed(KeyCode::KeyL) {
        let c = &mut store.config_mut::<LeafGizmos>().0.enabled;
        *c = !*c;
    }
    let depth = index.levels.len().saturating_sub(1) as u32;
    if input.just_pressed(KeyCode::BracketRight) && settings.level < depth {
        settings.level += 1;
    }
    if input.just_pressed(KeyCode::BracketLeft) && settings.level > 0 {
        settings.level -= 1;
    }
    let last = index.leaves.len().saturating_sub(1) as u32;
    if input.just_pressed(KeyCode::Period) && leaves.index < last {
        leaves.index += 1;
    }
    if input.just_pressed(KeyCode::Comma) && leaves.index > 0 {
        leaves.index -= 1;
    }
    for (key, mode) in [
        (KeyCode::KeyH, RenderMode::TraversalCost),
        (KeyCode::KeyO, RenderMode::Overlap),
        (KeyCode::KeyG, RenderMode::Work),
    ] {
        if input.just_pressed(key) {
            settings.mode = if settings.mode == mode {
                RenderMode::Shaded
            } else {
                mode
            };
        }
    }
}

fn aabb3d(b: &crate::geometry::Aabb) -> bevy::math::bounding::Aabb3d {
    bevy::math::bounding::Aabb3d {
        min: b.min,
        max: b.max,
    }
}

fn draw_level(
    mut gizmos: Gizmos<BvhLevelGizmos>,
    index: Res<BvhIndex>,
    settings: Res<ViewSettings>,
    leaves: Res<LeafView>,
) {
    if !gizmos.config.enabled {
        return;
    }
    let Some(nodes) = index.levels.get(settings.level as usize) else {
        return;
    };
    let overlap = settings.mode == RenderMode::Overlap;
    let color = level_color(settings.level);
    for &i in nodes.iter().take(leaves.max_boxes) {
        let c = if overlap {
            if index.overlaps_sibling[i as usize] {
                Color::srgb(1.0, 0.2, 0.15)
            } else {
                Color::srgba(0.6, 0.6, 0.6, 0.5)
            }
        } else {
            color
        };
        if let Some(n) = index.node(i) {
            gizmos.aabb_3d(aabb3d(&n.aabb()), index.to_world, c);
        }
    }
}

fn draw_leaves(mut gizmos: Gizmos<LeafGizmos>, index: Res<BvhIndex>, view: Res<LeafView>) {
    if !gizmos.config.enabled {
        return;
    }
    if view.all {
        for &i in index.leaves.iter().take(view.max_boxes) {
            if let Some(n) = index.node(i) {
                gizmos.aabb_3d(
                    aabb3d(&n.aabb()),
                    index.to_world,
                    Color::srgba(0.3, 0.9, 1.0, 0.6),
                );
            }
        }
        return;
    }
    let Some(&i) = index.leaves.get(view.index as usize) else {
        return;
    };
    let Some(n) = index.node(i) else {
        return;
    };
    gizmos.aabb_3d(
        aabb3d(&n.aabb()),
        index.to_world,
        Color::srgb(0.3, 0.9, 1.0),
    );
    if let Some(bvh) = index.bvh() {
        for (_, t) in bvh.leaf_triangles(i) {
            let [a, b, c] = t.map(|v| Vec3::from(index.to_world.transform_point3a(v)));
            gizmos.linestrip([a, b, c, a], Color::srgb(1.0, 0.85, 0.2));
        }
    }
}
