"""KAOS goal models with RELAX-ed requirements, and their evaluation as a logic tree.

A goal model (YAML, ``anunnaki: goal-model/1``) declares goals refined by AND/OR into
leaf goals whose *utility functions* are expressions over agents' attributes, obstacles that
obstruct goals, domain properties, and agents. A *platform binding* (``anunnaki:
binding/1``) says on which topic each agent publishes which fields, and which actuation
endpoints the platform offers — so one goal model serves several platforms (paper §3.4).

Typical use::

    from anunnaki.goals import load_goal_model, Evaluator

    model = load_goal_model("examples/rover/goals.yaml", "examples/rover/binding.yaml")
    ev = Evaluator(model)
    ev.observe("/utu/oracle/output", {"category": 1, "confidence": 0.9}, now=12.5)
    ev.tick(now=13.0)
    print(ev.root.status_name, ev.explain("G1").render())

RELAX operators from Python: :func:`build_operator` turns a :data:`RelaxSpec` into an
:class:`AtemporalOperator` (``utility(value)``), a :class:`MayOrOperator` or a
:class:`TemporalOperator` (``utility_at(p, e, now)`` over :class:`History` samples).

Formats: docs/goal-models.md; RELAX operators: docs/relax.md.
"""

from anunnaki.goals._evaluate import Evaluator, Explanation, NodeState, Status, status_name
from anunnaki.goals._expr import ABSENT, AttrRef, Expression, compile_expression, truth
from anunnaki.goals._freshness import RateEstimator, TopicFreshness, is_stale
from anunnaki.goals._model import (
    Agent,
    Binding,
    GoalModel,
    load_binding,
    load_goal_model,
    parse_binding,
    parse_goal_model,
)
from anunnaki.goals._model import _did_you_mean as did_you_mean
from anunnaki.goals._relax import (
    AtemporalOperator,
    History,
    MayOrOperator,
    RelaxOperator,
    RelaxSpec,
    TemporalOperator,
    build_operator,
)
from anunnaki.goals._schema import (
    AgentSpec,
    BindingSpec,
    DomainPropertySpec,
    EndpointSpec,
    GoalModelSpec,
    GoalSpec,
    ObstacleSpec,
    PayloadField,
    TopicBinding,
)

__all__ = [
    "ABSENT",
    "Agent",
    "AgentSpec",
    "AtemporalOperator",
    "AttrRef",
    "Binding",
    "BindingSpec",
    "DomainPropertySpec",
    "EndpointSpec",
    "Evaluator",
    "Explanation",
    "Expression",
    "GoalModel",
    "GoalModelSpec",
    "GoalSpec",
    "History",
    "MayOrOperator",
    "NodeState",
    "ObstacleSpec",
    "PayloadField",
    "RateEstimator",
    "RelaxOperator",
    "RelaxSpec",
    "Status",
    "TemporalOperator",
    "TopicBinding",
    "TopicFreshness",
    "build_operator",
    "compile_expression",
    "did_you_mean",
    "is_stale",
    "load_binding",
    "load_goal_model",
    "parse_binding",
    "parse_goal_model",
    "status_name",
    "truth",
]
