//! Where the ROS 2 node is seen: the DDS domain and the discovery range, from the same environment variables a ROS
//! 2 node reads, and the sensor's name in topic names.

/// How far the node announces itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiscoveryRange {
    /// Discovery and data on the loopback interface only: nodes on this machine see the sensor (nusense's default,
    /// unlike ROS's, which is the subnet).
    Localhost,
    /// Multicast discovery on every interface: any machine on the local network in the same domain sees it.
    Subnet,
}

/// The node's DDS settings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros2Settings {
    /// `ROS_DOMAIN_ID`, 0 when unset, as in ROS.
    pub domain_id: u16,
    pub range: DiscoveryRange,
}

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SettingsError {
    #[error("ROS_DOMAIN_ID={0:?} is not a domain id: use a whole number from 0 to {MAX_DOMAIN_ID}")]
    DomainId(String),
    #[error(
        "ROS_AUTOMATIC_DISCOVERY_RANGE={0:?} is not supported: use LOCALHOST (this machine, the default here) or \
         SUBNET (the local network)"
    )]
    Range(String),
}

/// The highest domain id DDS's port mapping allows (ports 7400 + 250 * domain must stay below 65536).
pub const MAX_DOMAIN_ID: u16 = 232;

impl Ros2Settings {
    /// The settings from this process's environment.
    pub fn from_env() -> Result<Self, SettingsError> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    /// The settings from environment variables as `var` returns them.
    ///
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE` (Iron and later) wins over `ROS_LOCALHOST_ONLY` (Humble); with neither the
    /// range is localhost: safe by default, a subnet only when asked for. `OFF` and `SYSTEM_DEFAULT` are refused
    /// rather than guessed at (a node nobody can discover would publish to no one).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Self, SettingsError> {
        let domain_id = match var("ROS_DOMAIN_ID")
            .map(|v| v.trim().to_owned())
            .filter(|v| !v.is_empty())
        {
            None => 0,
            Some(text) => text
                .parse::<u16>()
                .ok()
                .filter(|id| *id <= MAX_DOMAIN_ID)
                .ok_or(SettingsError::DomainId(text))?,
        };
        let range = match var("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .map(|v| v.trim().to_owned())
            .filter(|v| !v.is_empty())
        {
            Some(range) => match range.to_ascii_uppercase().as_str() {
                "LOCALHOST" => DiscoveryRange::Localhost,
                "SUBNET" => DiscoveryRange::Subnet,
                _ => return Err(SettingsError::Range(range)),
            },
            // ROS_LOCALHOST_ONLY=0 asks for the subnet as plainly as the newer variable does.
            None => match var("ROS_LOCALHOST_ONLY").as_deref().map(str::trim) {
                Some("0") => DiscoveryRange::Subnet,
                _ => DiscoveryRange::Localhost,
            },
        };
        Ok(Self { domain_id, range })
    }
}

/// The sensor's serial as one ROS name token (`/nusense/<token>/wrench`): letters, digits and single underscores,
/// not starting with a digit, as ROS 2 names require. Anything else becomes `_`; a leading digit gets `sn_` before
/// it; an empty serial is `unknown`.
pub fn sensor_token(serial: &str) -> String {
    let mut token = String::with_capacity(serial.len() + 3);
    for c in serial.chars() {
        let c = if c.is_ascii_alphanumeric() { c } else { '_' };
        if !(c == '_' && (token.is_empty() || token.ends_with('_'))) {
            token.push(c);
        }
    }
    while token.ends_with('_') {
        token.pop();
    }
    match token.chars().next() {
        None => "unknown".to_owned(),
        Some(first) if first.is_ascii_digit() => format!("sn_{token}"),
        Some(_) => token,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    fn settings(vars: &[(&str, &str)]) -> Result<Ros2Settings, SettingsError> {
        let vars: HashMap<String, String> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Ros2Settings::from_vars(|name| vars.get(name).cloned())
    }

    #[test]
    fn with_nothing_set_it_is_domain_0_on_this_machine_only() {
        assert_eq!(
            settings(&[]),
            Ok(Ros2Settings {
                domain_id: 0,
                range: DiscoveryRange::Localhost
            })
        );
    }

    #[test]
    fn the_domain_id_is_read_and_checked() {
        assert_eq!(settings(&[("ROS_DOMAIN_ID", "42")]).unwrap().domain_id, 42);
        assert_eq!(settings(&[("ROS_DOMAIN_ID", " 7 ")]).unwrap().domain_id, 7);
        assert_eq!(settings(&[("ROS_DOMAIN_ID", "")]).unwrap().domain_id, 0);
        assert_eq!(settings(&[("ROS_DOMAIN_ID", "232")]).unwrap().domain_id, 232);
        for bad in ["233", "-1", "robot", "1.5"] {
            assert_eq!(
                settings(&[("ROS_DOMAIN_ID", bad)]),
                Err(SettingsError::DomainId(bad.to_owned()))
            );
        }
    }

    #[test]
    fn the_range_follows_ros_and_the_newer_variable_wins() {
        let range = |vars: &[(&str, &str)]| settings(vars).map(|s| s.range);
        assert_eq!(
            range(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")]),
            Ok(DiscoveryRange::Subnet)
        );
        assert_eq!(
            range(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "localhost")]),
            Ok(DiscoveryRange::Localhost)
        );
        assert_eq!(range(&[("ROS_LOCALHOST_ONLY", "1")]), Ok(DiscoveryRange::Localhost));
        assert_eq!(range(&[("ROS_LOCALHOST_ONLY", "0")]), Ok(DiscoveryRange::Subnet));
        assert_eq!(
            range(&[
                ("ROS_LOCALHOST_ONLY", "0"),
                ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
            ]),
            Ok(DiscoveryRange::Localhost)
        );
        for refused in ["OFF", "SYSTEM_DEFAULT", "everywhere"] {
            assert_eq!(
                range(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", refused)]),
                Err(SettingsError::Range(refused.to_owned()))
            );
        }
    }

    #[test]
    fn serials_become_valid_ros_name_tokens() {
        assert_eq!(sensor_token("VB0001"), "VB0001");
        assert_eq!(sensor_token("0011AABB"), "sn_0011AABB");
        assert_eq!(sensor_token("nusense-01:a"), "nusense_01_a");
        assert_eq!(sensor_token("a--b__c"), "a_b_c");
        assert_eq!(sensor_token("_x_"), "x");
        assert_eq!(sensor_token("é"), "unknown");
        assert_eq!(sensor_token(""), "unknown");
    }
}
