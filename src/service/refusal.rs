//! Why a render was refused, as `/metrics` counts it
//! (`voxtrace_render_refusals_total{reason}`): the error kinds grouped by
//! what a user or operator would do about them.

/// A refusal of `POST /render`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The scene, its body, its image or its samples are over a limit: the
    /// same request will always be refused here (413, 422).
    Limit,
    /// The render ran out of its time budget (504).
    TimeBudget,
    /// Every slot busy and the queue full, or the wait for a slot too long:
    /// it may succeed later (503).
    Busy,
    /// The memory budget has no room for it now (503).
    Memory,
    /// The service is stopping (503).
    Draining,
}

impl Refusal {
    pub const ALL: [Refusal; 5] = [
        Refusal::Limit,
        Refusal::TimeBudget,
        Refusal::Busy,
        Refusal::Memory,
        Refusal::Draining,
    ];

    /// The refusal an error response reports, by its kind's machine name
    /// ([`super::ApiErrorKind::name`]); `None` for an error that is not a
    /// refusal (a malformed scene or query, an encoding failure).
    pub fn of_error(kind: &str) -> Option<Refusal> {
        let refusal = match kind {
            "limit" | "body_too_large" => Refusal::Limit,
            "time_budget" => Refusal::TimeBudget,
            "queue_full" | "queue_timeout" => Refusal::Busy,
            "body_memory" | "scene_memory" | "response_memory" => Refusal::Memory,
            "draining" => Refusal::Draining,
            _ => return None,
        };
        Some(refusal)
    }

    /// The `reason` label.
    pub fn label(self) -> &'static str {
        match self {
            Refusal::Limit => "limit",
            Refusal::TimeBudget => "time_budget",
            Refusal::Busy => "busy",
            Refusal::Memory => "memory",
            Refusal::Draining => "draining",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::error::ApiErrorKind;
    use super::*;

    /// Every kind of error a render can be refused with, by its real name,
    /// so that renaming a kind cannot silently stop counting it.
    #[test]
    fn every_refusing_kind_has_its_reason() {
        let cases = [
            (ApiErrorKind::Limit("x".into()), Some(Refusal::Limit)),
            (
                ApiErrorKind::BodyTooLarge { length: 2, max: 1 },
                Some(Refusal::Limit),
            ),
            (
                ApiErrorKind::TimeBudget {
                    budget_ms: 1,
                    elapsed_ms: 2,
                },
                Some(Refusal::TimeBudget),
            ),
            (ApiErrorKind::QueueFull, Some(Refusal::Busy)),
            (
                ApiErrorKind::QueueTimeout { waited_ms: 1 },
                Some(Refusal::Busy),
            ),
            (ApiErrorKind::BodyMemory, Some(Refusal::Memory)),
            (
                ApiErrorKind::SceneMemory { bytes: 1 },
                Some(Refusal::Memory),
            ),
            (
                ApiErrorKind::ResponseMemory { bytes: 1 },
                Some(Refusal::Memory),
            ),
            (ApiErrorKind::Draining, Some(Refusal::Draining)),
            (ApiErrorKind::Query("x".into()), None),
            (ApiErrorKind::Encode("x".into()), None),
        ];
        for (kind, refusal) in cases {
            assert_eq!(Refusal::of_error(kind.name()), refusal, "{kind:?}");
        }
        assert_eq!(Refusal::TimeBudget.label(), "time_budget");
    }
}
