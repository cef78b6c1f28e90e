//! Frame pacing: the app redraws on a steady clock (one frame every
//! [`ViewSettings::frame_ms`]) only while something changes (the camera moves, a key or button
//! is held, the scene, BVH or environment is loading, a picture is awaited); otherwise it waits
//! for input, window events or the trace worker's next picture (winit's reactive mode), so the
//! refining picture keeps the cores and a converged one costs next to no CPU.
//!
//! The clock: under a software graphics driver each frame costs the window 17-23 ms of CPU
//! (main thread, Bevy's task pools, the driver's threads). Drawing as fast as it could (about
//! 50 frames a second on two cores) took the window 0.81-0.88 of a core while the moving
//! picture changed on every second frame; paced at 30 ms it takes 0.59-0.76 and the trace
//! worker gets the rest (the `--orbit` figures in docs/viewer.md).

use std::time::Duration;

use bevy::prelude::*;
use bevy::winit::{EventLoopProxyWrapper, UpdateMode, WinitSettings, WinitUserEvent};

use super::scene::SceneLoading;
use super::trace::{TraceCamera, TraceStats, TraceSystems, TraceWorker, ViewSettings};

/// Switches between continuous and reactive updates.
pub struct PacingPlugin;

impl Plugin for PacingPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<KeepAwake>()
            .insert_resource(WinitSettings::continuous())
            .add_systems(Startup, wake_on_pictures)
            .add_systems(Last, pace.after(TraceSystems));
    }
}

/// Keeps the app updating continuously (scripted runs that count frames).
#[derive(Resource, Default, Clone, Copy, Debug)]
pub struct KeepAwake(pub bool);

/// Longest wait between two updates with nothing happening: a safety net only. Everything
/// that changes the picture wakes the loop itself (input and window events, the worker's
/// pictures), and loading keeps it running. Each idle frame costs the window a redraw, about
/// 40 ms of CPU under the software driver: a converged dragon used 4.5-4.8% of a core waking
/// every second, 0.5-0.7% every ten (`tracery view --orbit`'s idle figure).
const IDLE_WAIT: Duration = Duration::from_secs(10);

/// The worker wakes the event loop whenever it hands over a picture.
fn wake_on_pictures(worker: Res<TraceWorker>, proxy: Option<Res<EventLoopProxyWrapper>>) {
    let Some(proxy) = proxy else {
        return;
    };
    let proxy = (**proxy).clone();
    if let Ok(mut wake) = worker.0.shared.wake.lock() {
        *wake = Some(Box::new(move || {
            // The loop is gone when the app is closing: nothing to wake.
            let _ = proxy.send_event(WinitUserEvent::WakeUp);
        }));
    }
}

/// The update mode while something changes: a frame every `frame_ms` (counted from the start
/// of the last; events wait for the next frame), or continuous updates for 0.
fn paced(frame_ms: f32) -> UpdateMode {
    if frame_ms > 0.0 && frame_ms.is_finite() {
        UpdateMode::Reactive {
            wait: Duration::from_micros((frame_ms * 1e3).round() as u64),
            react_to_device_events: false,
            react_to_user_events: false,
            react_to_window_events: false,
        }
    } else {
        UpdateMode::Continuous
    }
}

#[allow(clippy::too_many_arguments)]
fn pace(
    keep: Res<KeepAwake>,
    view: Res<ViewSettings>,
    stats: Res<TraceStats>,
    loading: Res<SceneLoading>,
    keys: Res<ButtonInput<KeyCode>>,
    mouse: Res<ButtonInput<MouseButton>>,
    camera: Query<&Transform, With<TraceCamera>>,
    mut last_pose: Local<Option<Transform>>,
    mut settings: ResMut<WinitSettings>,
) {
    // The camera controller may write the transform every frame: compare the value.
    let pose = camera.iter().next().copied();
    let moved = pose != *last_pose;
    *last_pose = pose;
    let busy = keep.0
        || moved
        || stats.waiting.is_some()
        || loading.current().is_some()
        || keys.get_pressed().next().is_some()
        || mouse.get_pressed().next().is_some();
    let mode = if busy {
        paced(view.frame_ms)
    } else {
        UpdateMode::reactive(IDLE_WAIT)
    };
    if settings.focused_mode != mode {
        settings.focused_mode = mode;
        settings.unfocused_mode = mode;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_time_paces_updates_on_a_clock_and_zero_runs_them_continuously() {
        assert_eq!(
            paced(30.0),
            UpdateMode::Reactive {
                wait: Duration::from_millis(30),
                react_to_device_events: false,
                react_to_user_events: false,
                react_to_window_events: false,
            }
        );
        for none in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(paced(none), UpdateMode::Continuous, "{none}");
        }
    }
}
