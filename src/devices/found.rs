//! The devices `leman run` uses when no profile is given: the desktop stand-ins
//! ([`Profile::desktop_default`]), with a supported 3D mouse flying the view whenever one is
//! plugged in (the keys fly beside it: [`crate::devices::hub::RoleSample::axes`]).
//!
//! Only a 3Dconnexion HID SpaceMouse can be taken up this way: it is identified by its USB ids
//! and needs no settings. A serial tracker or 3D mouse cannot be identified from its port (see
//! [`crate::devices::enumerate`]) and opening an unknown port to ask could upset whatever is on
//! it; OpenTrack's UDP output cannot be seen before it sends. Those need a profile.

use crate::devices::enumerate::HidEntry;
use crate::devices::profile::{
    AxisMap, AxisMaps, DeviceKind, DeviceSpec, DriverSettings, HidSpec, Input, Profile, Role,
    TransportSpec,
};
use crate::devices::protocol::Protocol;

/// Name of the SpaceMouse entry in a found profile.
pub const SPACEMOUSE_DEVICE: &str = "spacemouse";

/// Dead zone of a found SpaceMouse's axes (of their ±1 range), as in
/// `devices/opentrack-spacemouse.toml`: the cap rests a little off centre.
const SPACEMOUSE_DEAD_ZONE: f32 = 0.05;

/// A SpaceMouse that goes this long without a report is stale (seconds): it sends nothing while
/// untouched, which is not a fault.
const SPACEMOUSE_STALE_AFTER_S: f64 = 3600.0;

/// The default profile: [`Profile::desktop_default`] with the navigation role on any supported
/// SpaceMouse, whether or not one is plugged in now. The hub opens one when it appears (its
/// reopening backoff, at most `reconnect_max_s` apart), and until then the keyboard stands in
/// for it ([`crate::devices::hub::RoleSample::stand_in`]); the keys fly beside it once it works.
/// So a SpaceMouse plugged in while the workstation runs is taken up too, and one unplugged and
/// plugged back in again. The profile does not depend on what is plugged in, so a session
/// recorded with it names the same devices on every machine.
pub fn default_profile() -> Profile {
    let mut profile = Profile::desktop_default();
    profile.name = "desktop+spacemouse".into();
    profile.description = "The desktop stand-ins, with any supported SpaceMouse flying the view \
                           beside the keyboard once it is plugged in; the mouse is the wand and \
                           the head sits 0.6 m in front of the screen centre."
        .into();
    profile.devices.push(DeviceSpec {
        name: SPACEMOUSE_DEVICE.into(),
        protocol: DeviceKind::Wire(Protocol::SpacemouseHid),
        transport: TransportSpec::Hid(HidSpec::default()),
        decoder: Default::default(),
        desktop: Default::default(),
        driver: DriverSettings {
            stale_after_s: SPACEMOUSE_STALE_AFTER_S,
            ..DriverSettings::default()
        },
    });
    let zone = AxisMap {
        dead_zone: SPACEMOUSE_DEAD_ZONE,
        ..AxisMap::default()
    };
    for binding in profile
        .roles
        .iter_mut()
        .filter(|b| b.role == Role::Navigation)
    {
        binding.device = SPACEMOUSE_DEVICE.into();
        binding.input = Input::Axes;
        binding.station = 1;
        binding.map = AxisMaps {
            x: zone,
            y: zone,
            z: zone,
            rx: zone,
            ry: zone,
            rz: zone,
        };
    }
    profile
}

/// One line for the user saying what [`default_profile`] finds among the HID devices `hid`
/// (from [`crate::devices::enumerate::list_hid`]) at start.
pub fn summary(hid: &[HidEntry]) -> String {
    let plugged_in = hid
        .iter()
        .find_map(|h| h.supported_model.as_deref().map(|m| (h, m)));
    match plugged_in {
        Some((entry, model)) => format!(
            "devices: {model} ({:04x}:{:04x}) flies the view beside the keyboard, the desktop \
             mouse is the wand",
            entry.vendor_id, entry.product_id
        ),
        None => "devices: the desktop mouse and keyboard; no supported 3D mouse is plugged in \
                 (a SpaceMouse plugged in later flies the view; trackers need --profile)"
            .into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::enumerate::match_hid;
    use crate::devices::spacemouse_hid::{VENDOR_3DCONNEXION, VENDOR_LOGITECH};
    use std::path::Path;

    fn hid(vendor_id: u16, product_id: u16) -> HidEntry {
        HidEntry::new(
            vendor_id,
            product_id,
            format!("/dev/hidraw-{vendor_id:04x}-{product_id:04x}"),
        )
    }

    /// A supported SpaceMouse's ids, from the decoder's own table.
    fn supported() -> (u16, u16) {
        (0..=u16::MAX)
            .flat_map(|p| [(VENDOR_3DCONNEXION, p), (VENDOR_LOGITECH, p)])
            .find(|(v, p)| match_hid(*v, *p).is_some())
            .expect("a supported model")
    }

    #[test]
    fn with_nothing_supported_plugged_in_the_summary_says_a_later_one_flies() {
        for found in [vec![], vec![hid(0x1234, 0x5678), hid(0x046d, 0x0001)]] {
            let got = summary(&found);
            assert!(
                got.contains("desktop mouse and keyboard") && got.contains("plugged in later"),
                "{got}"
            );
        }
    }

    #[test]
    fn the_spacemouse_flies_the_view_and_the_desktop_keeps_head_and_wand() {
        let (v, p) = supported();
        let profile = &default_profile();
        profile
            .validate(Path::new("found"))
            .expect("a valid profile");
        assert_eq!(
            profile.devices.len(),
            2,
            "one SpaceMouse however many interfaces"
        );
        let nav = profile.binding(Role::Navigation).expect("navigation");
        assert_eq!(nav.device, SPACEMOUSE_DEVICE);
        assert_eq!(nav.input, Input::Axes);
        assert_eq!(nav.map.rz.dead_zone, SPACEMOUSE_DEAD_ZONE);
        let mouse = &profile.devices[profile.device_index(SPACEMOUSE_DEVICE).expect("device")];
        assert_eq!(mouse.protocol, DeviceKind::Wire(Protocol::SpacemouseHid));
        assert_eq!(mouse.transport, TransportSpec::Hid(HidSpec::default()));
        let desktop = Profile::desktop_default();
        for role in [Role::Head, Role::Wand] {
            assert_eq!(profile.binding(role), desktop.binding(role), "{role:?}");
        }
        let said = summary(&[hid(0x1234, 0x5678), hid(v, p), hid(v, p)]);
        let model = match_hid(v, p).expect("supported").1;
        assert!(said.contains(model), "{said}");
        assert!(said.contains(&format!("{v:04x}:{p:04x}")), "{said}");
        // It is an ordinary profile: written out, it reads back the same.
        let text = profile.to_toml().expect("toml");
        assert_eq!(
            &Profile::parse(&text, Path::new("found.toml")).expect("parse"),
            profile
        );
    }
}
