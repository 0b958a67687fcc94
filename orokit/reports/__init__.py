"""orokit.reports"""
