//! BVH gizmos: the boxes of one level coloured by level (with the boxes that overlap a
//! sibling standing out in the overlap view), and the leaves (all, or one with its triangles
//! outlined). Each drawing is its own gizmo group with a key and an inspector toggle.

use std::sync::Arc;

use bevy::prelude::*;

use super::UiFocus;
use super::bvh::SceneBvh;
use super::scene::CurrentScene;
use super::trace::{RenderMode, ViewSettings};
use crate::bvh::Bvh;

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

/// The current BVH's nodes sorted by level, and its leaves, for drawing and the sliders.
#[derive(Resource, Default)]
pub struct BvhIndex {
    bvh: Option<Arc<Bvh>>,
    /// Node indices at each depth.
    pub levels: Vec<Vec<u32>>,
    /// Leaf node indices, in node order.
    pub leaves: Vec<u32>,
    /// For each node, whether its box overlaps its sibling's.
    pub overlaps_sibling: Vec<bool>,
}

impl BvhIndex {
    /// Indexes `bvh`.
    pub fn new(bvh: Arc<Bvh>) -> Self {
        let mut levels: Vec<Vec<u32>> = Vec::new();
        let mut leaves = Vec::new();
        let mut depth = vec![0u32; bvh.nodes.len()];
        let mut overlaps = vec![false; bvh.nodes.len()];
        if !bvh.is_empty() {
            for (i, n) in bvh.nodes.iter().enumerate() {
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
                    let (ba, bb) = (bvh.nodes[a].aabb(), bvh.nodes[b].aabb());
                    let o = ba.max.min(bb.max).cmpgt(ba.min.max(bb.min)).all();
                    overlaps[a] = o;
                    overlaps[b] = o;
                }
            }
        }
        Self {
            bvh: Some(bvh),
            levels,
            leaves,
            overlaps_sibling: overlaps,
        }
    }

    /// The indexed tree.
    pub fn bvh(&self) -> Option<&Arc<Bvh>> {
        self.bvh.as_ref()
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

/// Indexes each new tree, and brings the level and leaf shown into its range (a `--leaf` or
/// `--level` past it, or a rebuild with fewer leaves, would otherwise draw nothing), saying so.
fn index_bvh(
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
    mut index: ResMut<BvhIndex>,
    mut settings: ResMut<ViewSettings>,
    mut leaves: ResMut<LeafView>,
) {
    let Some(tree) = bvh.for_scene(current.generation) else {
        return;
    };
    if index.bvh.as_ref().is_some_and(|b| Arc::ptr_eq(b, tree)) {
        return;
    }
    *index = BvhIndex::new(tree.clone());
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
    let (Some(bvh), Some(nodes)) = (index.bvh(), index.levels.get(settings.level as usize)) else {
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
        gizmos.aabb_3d(
            aabb3d(&bvh.nodes[i as usize].aabb()),
            Transform::IDENTITY,
            c,
        );
    }
}

fn draw_leaves(mut gizmos: Gizmos<LeafGizmos>, index: Res<BvhIndex>, view: Res<LeafView>) {
    if !gizmos.config.enabled {
        return;
    }
    let Some(bvh) = index.bvh() else {
        return;
    };
    if view.all {
        for &i in index.leaves.iter().take(view.max_boxes) {
            gizmos.aabb_3d(
                aabb3d(&bvh.nodes[i as usize].aabb()),
                Transform::IDENTITY,
                Color::srgba(0.3, 0.9, 1.0, 0.6),
            );
        }
        return;
    }
    let Some(&i) = index.leaves.get(view.index as usize) else {
        return;
    };
    let n = &bvh.nodes[i as usize];
    gizmos.aabb_3d(
        aabb3d(&n.aabb()),
        Transform::IDENTITY,
        Color::srgb(0.3, 0.9, 1.0),
    );
    for (_, t) in bvh.leaf_triangles(i) {
        let [a, b, c] = t.map(Vec3::from);
        gizmos.linestrip([a, b, c, a], Color::srgb(1.0, 0.85, 0.2));
    }
}
