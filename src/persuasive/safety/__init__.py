"""Safety outside the model (docs/method.md §12): the shield that keeps a fallback in reserve
whatever a bounded human does (:mod:`.shield`), the planner's confidence in its human model
(:mod:`.confidence`), and the surrogate safety measures of a run (:mod:`.measures`)."""
