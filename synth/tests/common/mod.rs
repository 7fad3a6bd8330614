//! Shared by the geometry tests (`mod common;`).

use dear_synth::simulate::SimConfig;
use dear_synth::transport::RenderOptions;

/// One sample per pixel at its centre, direct light only: renders whose every pixel shows
/// exactly the surface its centre ray hits, for tests of geometry rather than of light.
pub fn direct_centre_rays() -> SimConfig {
    SimConfig {
        render: RenderOptions {
            spp: 1,
            indirect_spp: 0,
            max_bounces: 1,
            jitter: false,
            ..RenderOptions::default()
        },
        ..SimConfig::default()
    }
}
