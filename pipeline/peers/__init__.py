"""The methods the paper's introduction names, as plug-ins of the closed loop (``_target_``).

Each peer is a planner or a controller of its own module, built by the loop exactly as a user's
method is (``planner._target_`` / ``controller._target_``, settings in ``params``): nothing in
:mod:`pipeline.loop` knows them. They sit after the loop in the data flow (they import its
stages, never the other way round).

* :mod:`pipeline.peers.mpc_dcbf` - MPC with discrete-time control barrier functions
  (Zeng, Zhang and Sreenath, ACC 2021), on the goal line, no APF;
* :mod:`pipeline.peers.cbf_filter` - the MPC without APF, its first input filtered by a CBF-QP
  (Ames et al., ECC 2019);
* :mod:`pipeline.peers.velocity_obstacles` - velocity obstacles (Fiorini and Shiller, IJRR
  1998) as a planner feeding the same MPC;
* :mod:`pipeline.peers.dwa` - the dynamic window approach (Fox, Burgard and Thrun, IEEE RAM
  1997) on the Appendix-A track.

:mod:`pipeline.peers.side_rule` holds the side rule the two barrier peers share (an obstacle
dead ahead is passed on one side, so the linearized barrier keeps a lateral gradient).
"""
