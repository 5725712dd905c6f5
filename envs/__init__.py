"""Gymnasium environments and the rsl-rl adapter over warpcut's batched simulator."""
