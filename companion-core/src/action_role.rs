//! What each primitive action does for the code that must act on it: params/actions.toml declares
//! a `role` per action, checked at load, and the simulated world, the flight shell, the link's
//! mission-state estimator and the review ask the role, never the action's name (as they ask
//! [`crate::mission::RouteRole`] for the route's states).

use crate::spec::SpecError;
use std::path::Path;

/// What a primitive action does, as far as the code outside the models needs to know. Every
/// role but [`ActionRole::DetectObstacles`] and [`ActionRole::Track`] is played by exactly one
/// action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ActionRole {
    /// Stay on the ground: the models judge the vehicle unfit to launch.
    StayOnGround,
    /// Take off from base.
    TakeOff,
    /// Fly the route to its next waypoint.
    FollowRoute,
    /// Side-step an obstacle.
    AvoidObstacle,
    /// Run an obstacle detector (several actions may, one per sensor set).
    DetectObstacles,
    /// Search the planned landing zone (the paper's 'T' zone).
    SearchZone,
    /// Search an emergency landing area.
    SearchEmergencyZone,
    /// Land at the found zone, or where the vehicle is.
    Land,
    /// Replan, then land at the emergency zone.
    ReplanAndLand,
    /// Fly back to base and land there.
    ReturnToBase,
    /// Look for the target at the last waypoint.
    DetectTarget,
    /// Keep the target with one tracker version (the action a tracking state of
    /// params/mission.toml names; several actions do).
    Track,
}

impl ActionRole {
    /// Every role, in the order of the paper's action list.
    pub const ALL: [ActionRole; 12] = [
        ActionRole::StayOnGround,
        ActionRole::TakeOff,
        ActionRole::FollowRoute,
        ActionRole::AvoidObstacle,
        ActionRole::DetectObstacles,
        ActionRole::SearchZone,
        ActionRole::SearchEmergencyZone,
        ActionRole::Land,
        ActionRole::ReplanAndLand,
        ActionRole::ReturnToBase,
        ActionRole::DetectTarget,
        ActionRole::Track,
    ];

    /// The role's key in params/actions.toml (`role = "take_off"`).
    pub fn key(self) -> &'static str {
        match self {
            ActionRole::StayOnGround => "stay_on_ground",
            ActionRole::TakeOff => "take_off",
            ActionRole::FollowRoute => "follow_route",
            ActionRole::AvoidObstacle => "avoid_obstacle",
            ActionRole::DetectObstacles => "detect_obstacles",
            ActionRole::SearchZone => "search_zone",
            ActionRole::SearchEmergencyZone => "search_emergency_zone",
            ActionRole::Land => "land",
            ActionRole::ReplanAndLand => "replan_and_land",
            ActionRole::ReturnToBase => "return_to_base",
            ActionRole::DetectTarget => "detect_target",
            ActionRole::Track => "track",
        }
    }

    /// The role whose key is `key`.
    pub fn from_key(key: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.key() == key)
    }

    /// Whether exactly one action plays this role (the code asks for "the" action of it).
    pub fn is_single(self) -> bool {
        !matches!(self, ActionRole::DetectObstacles | ActionRole::Track)
    }

    /// Whether an action of this role ends the flight: the one answer for the world, the shell
    /// and the review.
    pub fn ends_flight(self) -> bool {
        matches!(
            self,
            ActionRole::Land | ActionRole::ReplanAndLand | ActionRole::ReturnToBase
        )
    }

    fn keys() -> String {
        Self::ALL.map(Self::key).join(", ")
    }
}

/// Which action plays each [`ActionRole`] (params/actions.toml `role`, checked): every action has
/// one role, and every single role is played by exactly one action.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActionRoles {
    /// Action id and its role, in file order.
    by_action: Vec<(String, ActionRole)>,
}

impl ActionRoles {
    /// Check the `role` of each action of `actions` (id, declared role key, in file order); `file`
    /// names the file in errors. A catalogue that declares no role at all is read by the rule of
    /// the decision logs written before roles were declared ([`ActionRoles::undeclared`]).
    pub fn compile(file: &Path, actions: &[(&str, Option<&str>)]) -> Result<Self, SpecError> {
        if actions.iter().all(|(_, r)| r.is_none()) {
            return Ok(Self::undeclared());
        }
        let mut by_action: Vec<(String, ActionRole)> = Vec::with_capacity(actions.len());
        for (i, &(id, key)) in actions.iter().enumerate() {
            let entry = format!("action[{i}].role");
            let Some(key) = key else {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "action `{id}` declares no `role`: once one action does, every one does (roles: {})",
                        ActionRole::keys()
                    ),
                ));
            };
            let Some(role) = ActionRole::from_key(key) else {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "`{key}` is not an action role (roles: {})",
                        ActionRole::keys()
                    ),
                ));
            };
            if role.is_single()
                && let Some((other, _)) = by_action.iter().find(|(_, r)| *r == role)
            {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!("the role `{key}` is already played by `{other}`: one action plays it"),
                ));
            }
            by_action.push((id.to_string(), role));
        }
        let missing: Vec<&str> = ActionRole::ALL
            .into_iter()
            .filter(|&r| r.is_single() && !by_action.iter().any(|(_, x)| *x == r))
            .map(ActionRole::key)
            .collect();
        if !missing.is_empty() {
            return Err(SpecError::new(
                file,
                "action",
                format!(
                    "no action plays the role(s) {}: each is played by one action",
                    missing.join(", ")
                ),
            ));
        }
        Ok(Self { by_action })
    }

    /// The rule of the decision logs written before params/actions.toml declared roles: the
    /// shipped action names of that time.
    pub fn undeclared() -> Self {
        let single = [
            ("stay_on_ground", ActionRole::StayOnGround),
            ("take_off", ActionRole::TakeOff),
            ("follow_trajectory", ActionRole::FollowRoute),
            ("avoid_obstacle", ActionRole::AvoidObstacle),
            ("detect_obstacles_fusion", ActionRole::DetectObstacles),
            ("search_zone_t", ActionRole::SearchZone),
            ("search_emergency_zone", ActionRole::SearchEmergencyZone),
            ("land", ActionRole::Land),
            ("replan_and_land", ActionRole::ReplanAndLand),
            ("detect_target", ActionRole::DetectTarget),
            ("return_to_base", ActionRole::ReturnToBase),
            ("detect_obstacles_lidar", ActionRole::DetectObstacles),
        ]
        .map(|(id, r)| (id.to_string(), r));
        let tracking = (0..10).map(|n| (format!("track_v{n}"), ActionRole::Track));
        Self {
            by_action: single.into_iter().chain(tracking).collect(),
        }
    }

    /// The action playing `role`: for a single role the one action, for a role several actions
    /// play the first in file order. Empty only for a plural role no action plays.
    pub fn action(&self, role: ActionRole) -> &str {
        self.by_action
            .iter()
            .find(|(_, r)| *r == role)
            .map_or("", |(id, _)| id.as_str())
    }

    /// The role action `id` plays; None for an id the catalogue does not hold.
    pub fn role_of(&self, id: &str) -> Option<ActionRole> {
        self.by_action
            .iter()
            .find(|(a, _)| a == id)
            .map(|(_, r)| *r)
    }

    /// Whether action `id` plays `role`.
    pub fn is(&self, id: &str, role: ActionRole) -> bool {
        self.role_of(id) == Some(role)
    }

    /// Whether some action of `actions` plays `role`.
    pub fn any<I>(&self, actions: I, role: ActionRole) -> bool
    where
        I: IntoIterator,
        I::Item: AsRef<str>,
    {
        actions.into_iter().any(|a| self.is(a.as_ref(), role))
    }

    /// Whether action `id` ends the flight ([`ActionRole::ends_flight`]).
    pub fn ends_flight(&self, id: &str) -> bool {
        self.role_of(id).is_some_and(ActionRole::ends_flight)
    }

    /// The first action of `actions` that ends the flight.
    pub fn first_ending<I>(&self, actions: I) -> Option<I::Item>
    where
        I: IntoIterator,
        I::Item: AsRef<str>,
    {
        actions.into_iter().find(|a| self.ends_flight(a.as_ref()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A catalogue with every role, under names that are not the shipped ones.
    const SHIPPED: [(&str, &str); 8] = [
        ("stay", "stay_on_ground"),
        ("go", "take_off"),
        ("fly", "follow_route"),
        ("dodge", "avoid_obstacle"),
        ("look", "detect_obstacles"),
        ("look2", "detect_obstacles"),
        ("zone", "search_zone"),
        ("ezone", "search_emergency_zone"),
    ];
    const REST: [(&str, &str); 6] = [
        ("down", "land"),
        ("edown", "replan_and_land"),
        ("home", "return_to_base"),
        ("seek", "detect_target"),
        ("t0", "track"),
        ("t1", "track"),
    ];

    /// The catalogue above, with action `replace.0`'s role replaced by `replace.1`.
    fn table(
        replace: Option<(&'static str, Option<&'static str>)>,
    ) -> Vec<(&'static str, Option<&'static str>)> {
        SHIPPED
            .iter()
            .chain(&REST)
            .map(|&(id, r)| match replace {
                Some((x, new)) if x == id => (id, new),
                _ => (id, Some(r)),
            })
            .collect()
    }

    fn compile(t: &[(&str, Option<&str>)]) -> Result<ActionRoles, SpecError> {
        ActionRoles::compile(Path::new("p/actions.toml"), t)
    }

    #[test]
    fn roles_are_read_from_the_declarations_not_the_names() {
        let roles = compile(&table(None)).unwrap();
        assert_eq!(roles.action(ActionRole::TakeOff), "go");
        assert_eq!(roles.action(ActionRole::FollowRoute), "fly");
        assert_eq!(roles.role_of("t1"), Some(ActionRole::Track));
        assert_eq!(roles.role_of("take_off"), None);
        assert!(roles.any(&["fly", "look2"], ActionRole::DetectObstacles));
        assert!(!roles.any(&["fly"], ActionRole::DetectObstacles));
        let ending: Vec<&str> = ["down", "edown", "home", "dodge", "seek"]
            .into_iter()
            .filter(|a| roles.ends_flight(a))
            .collect();
        assert_eq!(ending, ["down", "edown", "home"]);
        assert_eq!(roles.first_ending(&["fly", "home", "down"]), Some(&"home"));
    }

    #[test]
    fn an_action_without_a_role_is_refused_once_another_declares_one() {
        let e = compile(&table(Some(("zone", None)))).unwrap_err();
        assert_eq!(e.entry, "action[6].role");
        assert!(e.reason.contains("`zone` declares no `role`"), "{e}");
        // None at all: the rule of old logs.
        let none: Vec<(&str, Option<&str>)> = vec![("x", None)];
        assert_eq!(compile(&none).unwrap(), ActionRoles::undeclared());
    }

    #[test]
    fn an_unknown_role_is_refused_with_its_entry() {
        let e = compile(&table(Some(("fly", Some("fly_route"))))).unwrap_err();
        assert!(e.file.ends_with("actions.toml"));
        assert_eq!(e.entry, "action[2].role");
        assert!(
            e.reason.contains("`fly_route` is not an action role"),
            "{e}"
        );
    }

    #[test]
    fn a_single_role_played_twice_or_not_at_all_is_refused() {
        let e = compile(&table(Some(("ezone", Some("search_zone"))))).unwrap_err();
        assert_eq!(e.entry, "action[7].role");
        assert!(e.reason.contains("already played by `zone`"), "{e}");
        let e = compile(&table(Some(("home", Some("land"))))).unwrap_err();
        assert!(e.reason.contains("already played by `down`"), "{e}");
        let e = compile(&table(Some(("seek", Some("track"))))).unwrap_err();
        assert_eq!(e.entry, "action");
        assert!(e.reason.contains("detect_target"), "{e}");
    }

    #[test]
    fn the_rule_of_old_logs_names_the_shipped_actions() {
        let old = ActionRoles::undeclared();
        assert_eq!(old.action(ActionRole::TakeOff), "take_off");
        assert_eq!(old.action(ActionRole::FollowRoute), "follow_trajectory");
        assert!(old.ends_flight("return_to_base") && !old.ends_flight("avoid_obstacle"));
        assert_eq!(old.role_of("track_v3"), Some(ActionRole::Track));
    }
}
