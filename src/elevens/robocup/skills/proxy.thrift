// elevens' side of the decision protocol that a skills proxy player speaks each cycle:
// librcsc keeps the world model and executes the skills, elevens chooses them.
//
// Only the messages and fields elevens reads or writes are here. Field ids and wire types
// follow the proxy's protocol (IDL "version 1.10" of CLSFramework's soccer-simulation-proxy),
// so the bytes on the wire are the same; anything else the proxy sends is skipped unread.
// Binary protocol over a buffered (unframed) socket. Coordinates are librcsc's: our team
// always attacks towards +x, whatever side the server gave it.

namespace py elevens_proxy

// ---- enumerations (i32 on the wire) ----

enum Side {
  UNKNOWN = 0,
  LEFT = 1,
  RIGHT = 2
}

enum AgentType {
  PlayerT = 0,
  CoachT = 1,
  TrainerT = 2
}

// The play modes elevens tells apart; other values arrive as plain integers.
enum GameModeType {
  BeforeKickOff = 0,
  TimeOver = 1,
  PlayOn = 2,
  KickOff_ = 3,
  KickIn_ = 4,
  FreeKick_ = 5,
  CornerKick_ = 6,
  GoalKick_ = 7,
  AfterGoal_ = 8,
  OffSide_ = 9,
  PenaltyKick_ = 10,
  GoalieCatch_ = 30
}

// ---- what the proxy tells us ----

// A point or a velocity; the proxy also fills distance and angle (3, 4), which we derive.
struct RpcVector2D {
  1: double x,
  2: double y
}

// Who a connection is: the proxy sends it back with every later call.
struct RegisterResponse {
  1: i32 client_id,
  2: AgentType agent_type,
  3: string team_name,
  4: i32 uniform_number
}

struct RegisterRequest {
  1: AgentType agent_type,
  2: string team_name,
  3: i32 uniform_number,
  4: i32 rpc_version
}

struct Ball {
  1: RpcVector2D position,
  5: RpcVector2D velocity,
  8: i32 pos_count
}

// A teammate or an opponent as this player's world model has it. `id` is librcsc's object
// id (the intercept table names players by it), not the shirt number.
struct Player {
  1: RpcVector2D position,
  4: RpcVector2D velocity,
  6: i32 pos_count,
  14: i32 id,
  15: Side side,
  16: i32 uniform_number,
  18: bool is_goalie,
  19: double body_direction,
  28: i32 ball_reach_steps
}

// The deciding player itself.
struct Self {
  1: RpcVector2D position,
  4: RpcVector2D velocity,
  14: i32 uniform_number,
  16: bool is_goalie,
  17: double body_direction,
  29: double stamina,
  30: bool is_kickable,
  32: double tackle_probability
}

// librcsc's predictions of who reaches the ball first, in cycles.
struct InterceptTable {
  1: i32 self_reach_steps,
  2: i32 first_teammate_reach_steps,
  4: i32 first_opponent_reach_steps,
  6: i32 first_teammate_id,
  8: i32 first_opponent_id
}

struct WorldModel {
  1: InterceptTable intercept_table,
  4: Side our_side,
  6: Self myself,
  7: Ball ball,
  8: list<Player> teammates,
  9: list<Player> opponents,
  14: i32 their_goalie_uniform_number,
  15: double offside_line_x,
  19: Side last_kick_side,
  20: i32 last_kicker_uniform_number,
  21: i32 cycle,
  22: GameModeType game_mode_type,
  25: bool is_our_set_play,
  27: i32 stoped_cycle,
  28: i32 our_team_score,
  29: i32 their_team_score,
  30: bool is_penalty_kick_mode,
  36: bool kickable_teammate_existance,
  37: bool kickable_opponent_existance
}

// One player's request of a cycle. need_preprocess: the proxy would run its own
// perception fallbacks (frozen by a tackle, lost self or ball, before kick-off) unless told not to.
struct State {
  1: RegisterResponse register_response,
  2: WorldModel world_model,
  4: bool need_preprocess
}

// Sent once after registering; we only keep who sent them.
struct InitMessage {
  1: RegisterResponse register_response
}

struct ServerParam {
  1: RegisterResponse register_response
}

struct PlayerParam {
  1: RegisterResponse register_response
}

struct PlayerType {
  1: RegisterResponse register_response
}

struct Empty {}

// ---- what we answer: librcsc's skills and a few ready behaviours ----

struct Move {
  1: double x,
  2: double y
}

struct Body_GoToPoint {
  1: RpcVector2D target_point,
  2: double distance_threshold,
  3: double max_dash_power
}

// The multi-step kick: shots and passes.
struct Body_SmartKick {
  1: RpcVector2D target_point,
  2: double first_speed,
  3: double first_speed_threshold,
  4: i32 max_steps
}

struct Body_Dribble {
  1: RpcVector2D target_point,
  2: double distance_threshold,
  3: double dash_power,
  4: i32 dash_count,
  5: bool dodge
}

// kick_target_point: the point the ball is kept away from (the nearest opponent).
struct Body_HoldBall {
  1: bool do_turn,
  2: RpcVector2D turn_target_point,
  3: RpcVector2D kick_target_point
}

struct Body_Intercept {
  1: bool save_recovery,
  2: RpcVector2D face_point
}

struct Body_TackleToPoint {
  1: RpcVector2D target_point,
  2: double min_probability,
  3: double min_speed
}

struct Body_TurnToBall {
  1: i32 cycle
}

struct Neck_TurnToBallOrScan {
  1: i32 count_threshold
}

struct View_Wide {}

// Ready behaviours of the proxy: the goalie, set pieces, penalties.
struct HeliosGoalie {}

struct HeliosSetPlay {}

struct HeliosPenalty {}

// helios-base's shot search (Bhv_StrictCheckShoot).
struct HeliosShoot {}

// helios-base's off-ball play (Bhv_BasicMove): a tackle, a run at the ball when it is the
// player's to win, else its formation position at helios's stamina-saving dash power.
struct HeliosBasicMove {}

// helios-base's on-ball planner: its action-chain search over the generators switched on here
// (evaluation, field 13, left unset: helios's own field evaluator), then the best chain's
// first action. With server_side_decision the proxy asks GetBestPlannerAction instead.
struct HeliosOffensivePlanner {
  1: bool direct_pass,
  2: bool lead_pass,
  3: bool through_pass,
  4: bool short_dribble,
  5: bool long_dribble,
  6: bool cross,
  7: bool simple_pass,
  8: bool simple_dribble,
  9: bool simple_shoot,
  10: bool server_side_decision,
  11: i32 max_depth,
  12: i32 max_nodes
}

// One entry of an answer; exactly one field is set. Body entries are tried in order until
// one executes; neck and view entries apply on top.
struct PlayerAction {
  6: optional Move move,
  16: optional Body_GoToPoint body_go_to_point,
  17: optional Body_SmartKick body_smart_kick,
  28: optional Body_Dribble body_dribble,
  30: optional Body_HoldBall body_hold_ball,
  31: optional Body_Intercept body_intercept,
  35: optional Body_TackleToPoint body_tackle_to_point,
  37: optional Body_TurnToBall body_turn_to_ball,
  44: optional Neck_TurnToBallOrScan neck_turn_to_ball_or_scan,
  54: optional View_Wide view_wide,
  55: optional HeliosGoalie helios_goalie,
  58: optional HeliosShoot helios_shoot,
  59: optional HeliosOffensivePlanner helios_offensive_planner,
  61: optional HeliosBasicMove helios_basic_move,
  62: optional HeliosSetPlay helios_set_play,
  63: optional HeliosPenalty helios_penalty
}

// The ignore_* flags switch off the proxy's own reflexes, run before our actions.
struct PlayerActions {
  1: list<PlayerAction> actions,
  2: bool ignore_preprocess,
  3: bool ignore_doforcekick,
  4: bool ignore_doHeardPassRecieve,
  5: bool ignore_doIntention,
  6: bool ignore_shootInPreprocess
}

// The online coach (optional): its only use is the proxy's own substitution of player types.
struct DoHeliosSubstitute {}

struct CoachAction {
  2: optional DoHeliosSubstitute do_helios_substitute
}

struct CoachActions {
  1: list<CoachAction> actions
}

// ---- the planner's candidates, when elevens chooses among them (server_side_decision) ----

enum RpcActionCategory {
  AC_Hold = 0,
  AC_Dribble = 1,
  AC_Pass = 2,
  AC_Shoot = 3,
  AC_Clear = 4,
  AC_Move = 5,
  AC_NoAction = 6
}

// One action of a chain; parent_index -1 for a chain's first action.
struct RpcCooperativeAction {
  1: RpcActionCategory category,
  2: i32 index,
  3: i32 sender_unum,
  4: i32 target_unum,
  5: RpcVector2D target_point,
  6: double first_ball_speed,
  10: i32 duration_step,
  16: i32 parent_index
}

// The state the planner predicts after the action.
struct RpcPredictState {
  1: i32 spend_time,
  2: i32 ball_holder_unum,
  3: RpcVector2D ball_position,
  4: RpcVector2D ball_velocity,
  5: double our_defense_line_x,
  6: double our_offense_line_x
}

// One node of the planner's search: the chain ending in action, helios's evaluation of it.
struct RpcActionState {
  1: RpcCooperativeAction action,
  2: RpcPredictState predict_state,
  3: double evaluation
}

// Every node the planner searched, by its index, and the asking player's state.
struct BestPlannerActionRequest {
  1: RegisterResponse register_response,
  2: map<i32, RpcActionState> pairs,
  3: State state
}

// The chosen node: the proxy plays the first action of the chain that ends there.
struct BestPlannerActionResponse {
  1: i32 index
}

// ---- the calls a proxy makes ----

service Game {
  // Once per connection, then the four Send* calls.
  RegisterResponse Register(1: RegisterRequest request),
  Empty SendServerParams(1: ServerParam server_param),
  Empty SendPlayerParams(1: PlayerParam player_param),
  Empty SendPlayerType(1: PlayerType player_type),
  Empty SendInitMessage(1: InitMessage init_message),
  // Every cycle: one player's decision.
  PlayerActions GetPlayerActions(1: State state),
  CoachActions GetCoachActions(1: State state),
  Empty SendByeCommand(1: RegisterResponse register_response),
  // With HeliosOffensivePlanner.server_side_decision: which searched chain to play.
  BestPlannerActionResponse GetBestPlannerAction(1: BestPlannerActionRequest best_planner_action_request)
}
