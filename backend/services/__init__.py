"""One function per user action: load state from the database, call the learning core, move the robot, commit once.

Participants go through consent -> instructions -> one teaching session per task (practice,
demonstrations, queries, tests; core.session enforces their order) -> questionnaire -> done. Every
action appends to the participant's event log in the same transaction that changes their state, so
an acknowledged action is never lost. A client-supplied idempotency key makes retries harmless.
Modules: context (shared context), studies, state (the state view and action machinery), teaching,
participants, lifecycle (withdrawal, erasure, pilot reset, timeouts), viewing (the 3D view and the one-tab
rule), monitoring, exports, codebook.
"""

from .context import TAB_LEASE_SECONDS, Context, TabLeases, app_version
from .exports import (
    BELIEF_COLUMNS,
    EVENT_COLUMNS,
    EXPORT_COLUMNS,
    EXPORTS,
    PARTICIPANT_COLUMNS,
    QUESTIONNAIRE_COLUMNS,
    export_rows,
)
from .assistance import help_on, restore_participant
from .codebook import CODEBOOK_COLUMNS, codebook_rows, export_files
from .lifecycle import erase_participant, erasure_log, expire_timeouts, reset_pilot, withdraw
from .notify import LocalNotifier
from .monitoring import belief_summary, list_participants
from .participants import (answer_questionnaire, answer_quiz, finish_instructions, give_consent, join_study,
                           participant_id_of)
from .state import STAGES, Expect, delete_recordings, participant_state
from .freshness import ChangeSnapshot, activity_tag, change_snapshot, current_state_tag, robot_activity, tagged_state
from .statistics import study_statistics
from .studies import (
    archive_study,
    delete_study,
    ASSIGNMENTS,
    DEFAULT_CONSENT,
    DEMO_QUESTIONNAIRE,
    DEMO_STUDY_ID,
    ITEM_KINDS,
    STUDY_STATUSES,
    TASK_FORMULAS,
    TASK_INSTRUCTIONS,
    TASK_KEYS,
    TASK_NAMES,
    clone_study,
    close_study,
    create_study,
    describe_formula,
    editable_spec,
    get_study,
    list_studies,
    open_study,
    seed_demo_study,
    study_problems,
    study_view,
    update_study,
)
from .flat_view import flat_view
from .teaching import assess_execution, finish_demonstration, place_object, start_execution
from .viewing import (
    claim_tab,
    current_motion,
    next_robot_change,
    open_viewer,
    prepare_viewer,
    participant_uid_of,
    release_tab,
    replay_execution,
)

__all__ = [
    "archive_study",
    "delete_study",
    "study_statistics",
    "help_on",
    "restore_participant",
    "CODEBOOK_COLUMNS",
    "answer_quiz",
    "clone_study",
    "codebook_rows",
    "describe_formula",
    "editable_spec",
    "erase_participant",
    "erasure_log",
    "expire_timeouts",
    "export_files",
    "reset_pilot",
    "study_problems",
    "update_study",
    "withdraw",
    "ASSIGNMENTS",
    "BELIEF_COLUMNS",
    "Context",
    "DEFAULT_CONSENT",
    "DEMO_QUESTIONNAIRE",
    "DEMO_STUDY_ID",
    "EVENT_COLUMNS",
    "EXPORTS",
    "EXPORT_COLUMNS",
    "Expect",
    "ITEM_KINDS",
    "LocalNotifier",
    "PARTICIPANT_COLUMNS",
    "QUESTIONNAIRE_COLUMNS",
    "STAGES",
    "STUDY_STATUSES",
    "TAB_LEASE_SECONDS",
    "TASK_FORMULAS",
    "TASK_INSTRUCTIONS",
    "TASK_KEYS",
    "TASK_NAMES",
    "TabLeases",
    "answer_questionnaire",
    "app_version",
    "assess_execution",
    "belief_summary",
    "claim_tab",
    "current_motion",
    "flat_view",
    "close_study",
    "create_study",
    "delete_recordings",
    "export_rows",
    "finish_demonstration",
    "finish_instructions",
    "get_study",
    "give_consent",
    "join_study",
    "list_participants",
    "list_studies",
    "next_robot_change",
    "open_study",
    "open_viewer",
    "prepare_viewer",
    "participant_uid_of",
    "participant_state",
    "participant_id_of",
    "place_object",
    "release_tab",
    "replay_execution",
    "ChangeSnapshot",
    "change_snapshot",
    "activity_tag",
    "current_state_tag",
    "robot_activity",
    "tagged_state",
    "seed_demo_study",
    "start_execution",
    "study_view",
]
