"""Physics execution: timed plans run in a Drake simulation with contact; are the cans recycled?"""
