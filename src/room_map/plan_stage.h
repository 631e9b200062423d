#pragma once
/// The planning stage with the session store: build the room map of a case
/// and store it as a RoomMapRecord of a plan; load the map back for
/// localisation. Used by `arpos plan`, `arpos localize` and the run-case
/// controller.
///
/// The map is built before anything is stored: a case whose room cannot be
/// mapped leaves the store as it was. The patient, plan, room recording, room
/// map and their audit entries are then written in one transaction.
///
/// Patients and plans follow the run-case controller's convention: the
/// patient's external id is the case folder's name unless given; a plan
/// created here is named "<case> plan" and holds the case's reference model
/// and target pose.

#include <filesystem>
#include <optional>
#include <string>

#include "controllers/controller.h"
#include "geometry/triangle_mesh.h"
#include "room_map/room_map.h"
#include "room_map/room_map_builder.h"
#include "sensor/case_folder.h"
#include "store/database.h"
#include "store/roles.h"

namespace arpos {

/// What a caller may tune about the map (the rest comes from the case).
struct RoomMapStageOptions {
  int frame_step = 1;       ///< use every n-th room frame
  int max_frames = 0;       ///< 0 = all
  int threads = 2;
  bool use_keypoints = true;
  int max_landmarks = 4000;
  /// Leave out landmarks around the isocentre at the target pose (couch top
  /// and patient move during positioning; see CouchExclusionBox).
  bool exclude_couch = true;

  std::string Check() const;  ///< empty if valid
};

/// The builder's options for `folder` with the stage options applied.
RoomMapBuildOptions MakeRoomMapBuildOptions(const CaseFolder& folder, const RoomMapStageOptions& options);

/// Builds the map of `folder.room_dir`; needs no store. Throws InputError (no
/// room sequence, unreadable frame, origin marker never seen), Cancelled.
RoomMapBuildResult BuildCaseRoomMap(const CaseFolder& folder, const RoomMapStageOptions& options,
                                    const ControllerCallbacks& callbacks = {});

/// Stores a built map under `plan` (`room_recording`: the stored room
/// recording it was built from, if any) with its `build_room_map` audit
/// entry, atomically; inside a caller's WithTransaction it commits with the
/// caller's other rows. The record also carries the room frame's uncertainty
/// from `build.report` (empty where the build could not measure it).
RoomMapId StoreRoomMap(Database* database, PlanId plan, std::optional<RecordingId> room_recording,
                       const CaseFolder& folder, const RoomMapBuildResult& build, const std::string& actor);

/// The rows planning creates for a case, shared by `arpos plan` and run-case;
/// call them inside the caller's transaction. The patient and the plan come
/// with their audit entries (add_patient, add_plan).
/// A patient with external id `external_id` (display name the same).
PatientId AddCasePatient(Database* database, const CaseFolder& folder, const std::string& external_id,
                         const std::string& actor);
/// A plan named "<case_name> plan" holding `model` (the case's reference
/// model, model frame, metres) and the case's target pose.
PlanId AddCasePlan(Database* database, PatientId patient, const CaseFolder& folder, const TriangleMesh& model,
                   const std::string& case_name, const std::string& actor);
/// The case's room/ sequence as the room recording of `plan`.
RecordingId AddRoomRecording(Database* database, PlanId plan, const CaseFolder& folder);

/// `arpos plan CASE`: the case's patient and plan (created if the store has
/// none for the case, or the given plan), the room recording, the map.
/// Builds the map first, then writes every row in one transaction; throws
/// (InputError, Cancelled, StoreError) with nothing stored.
struct PlanRoomMapOptions {
  std::filesystem::path case_dir;
  std::optional<PlanId> plan_id;    ///< else the newest plan of the case's patient, created if none
  std::string patient_external_id;  ///< empty: the case folder's name
  /// A new plan for the patient even if it has an unapproved one.
  bool new_plan = false;
  RoomMapStageOptions stage;
  /// Who plans (a technician, or a research run; store/roles.h).
  Operator op;

  std::string Check() const;
};

struct PlanRoomMapResult {
  PatientId patient_id;
  PlanId plan_id;
  bool created_plan = false;
  std::string plan_choice;  ///< which plan and why, for the user
  RecordingId recording_id;
  RoomMapId room_map_id;
  RoomMapBuildResult build;
  std::string Summary() const;
};

PlanRoomMapResult RunPlanRoomMap(const PlanRoomMapOptions& options, Database* database,
                                 const ControllerCallbacks& callbacks = {});

/// The plan a session uses: `given` if set, else the one plan of the
/// patient `patient_external_id` that has a room map and, if
/// `need_approved`, is approved (with !need_approved, approved plans are
/// preferred when there are any). Never a guess: more than one candidate is
/// refused with their ids ("choose one with --plan ID"); none is refused
/// with what is missing (no plan, no room map, not approved and who
/// approves). `said` receives a line for the user: which plan and why.
/// `newest_if_several`: a research run takes the newest of several and says
/// so (scripts that plan a case twice keep working); clinical roles choose.
PlanId ChoosePlanForSession(Database* database, std::optional<PlanId> given, const std::string& patient_external_id,
                            bool need_approved, bool newest_if_several = false, std::string* said = nullptr);

/// The room map to localise against: the newest map of `plan` if given, else
/// of the newest plan (with a map) of the patient `patient_external_id`, else
/// of the newest plan in the store that has one. Throws InputError saying what
/// is missing ("plan 3 has no room map: run `arpos plan CASE` first") when
/// there is none. `plan_out`/`map_id_out` receive what was chosen.
RoomMap LoadRoomMapForLocalization(Database* database, std::optional<PlanId> plan,
                                   const std::string& patient_external_id,
                                   PlanId* plan_out = nullptr, RoomMapId* map_id_out = nullptr);

/// The case folder holding a sequence folder: the nearest ancestor of
/// `sequence_dir` (itself included) with a case.yaml; nullopt if none.
std::optional<std::filesystem::path> FindCaseRoot(const std::filesystem::path& sequence_dir);

/// The patient external id run-case and plan use for a case folder: its name.
std::string CasePatientId(const std::filesystem::path& case_root);

}  // namespace arpos
