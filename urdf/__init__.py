"""The table's URDF (eight rods of two joints, 22 figurines, the ball) and the script that
generates it from foosball_gym.table's numbers."""
