"""Assurance cases: the goal model argued in GSN, every claim tied to measured evidence.

``anunnaki assurance build LAUNCH.yaml --out case/`` turns a launch's goal model into a GSN
argument (goals, strategies over AND/OR refinements, agents as context, obstacles as hazards
argued through their resolutions, domain properties as assumptions, RELAX tolerances as
acceptance criteria) and develops it with evidence read from the project's own
measurements, filed under the AMLAS stages (a criteria file, ``assurance.yaml`` beside the
launch, says which figure develops which goal against what criterion). A goal without
evidence is *undeveloped*; evidence whose artefact changed since it was measured is
*stale*; neither is ever shown as supported.

Typical use::

    from anunnaki.assurance import build_case, check_case, write_case

    case = build_case("examples/uav/sim.yaml")
    write_case(case, "case/")
    print(case.coverage())
    print(check_case(case))     # [] while no artefact changed
    live = evaluate(case, evaluator_states, active_model="uav-fog", perceived="fog")

Nothing is measured and no model is loaded: figures are read from JSON, files hashed.
Formats and the GSN mapping: docs/assurance.md.
"""

from anunnaki.assurance._build import CRITERIA_FILE, build_case, case_from_model, goal_id
from anunnaki.assurance._case import (
    CASE_FORMAT,
    STATUSES,
    Artefact,
    Case,
    Evidence,
    Node,
    combine,
    propagate,
    read_case,
)
from anunnaki.assurance._check import Change, check_case
from anunnaki.assurance._criteria import (
    CRITERIA_FORMAT,
    STAGES,
    Criteria,
    EvidenceSpec,
    load_criteria,
    parse_criteria,
)
from anunnaki.assurance._export import (
    gsn_document,
    gsn_yaml,
    render_html,
    render_svg,
    write_case,
)
from anunnaki.assurance._live import LIVE_STATUSES, LiveStatus, evaluate
from anunnaki.assurance._monitor import (
    HOLDING,
    CaseMonitor,
    LiveCase,
    goal_states,
    load_live_case,
    perceived_of,
    top_claims,
)
from anunnaki.assurance._relax_text import Acceptance, acceptance
from anunnaki.assurance._validate import validate, validate_gsn, validate_gsn_file

__all__ = [
    "CASE_FORMAT",
    "CRITERIA_FILE",
    "CRITERIA_FORMAT",
    "HOLDING",
    "LIVE_STATUSES",
    "STAGES",
    "STATUSES",
    "Acceptance",
    "Artefact",
    "Case",
    "CaseMonitor",
    "Change",
    "Criteria",
    "Evidence",
    "EvidenceSpec",
    "LiveCase",
    "LiveStatus",
    "Node",
    "acceptance",
    "build_case",
    "case_from_model",
    "check_case",
    "combine",
    "evaluate",
    "goal_id",
    "goal_states",
    "gsn_document",
    "gsn_yaml",
    "load_criteria",
    "load_live_case",
    "parse_criteria",
    "perceived_of",
    "propagate",
    "read_case",
    "render_html",
    "render_svg",
    "top_claims",
    "validate",
    "validate_gsn",
    "validate_gsn_file",
    "write_case",
]
